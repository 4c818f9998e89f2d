// iso-bench-halo SCAN [--level L] [--min-points N] [--marked-only]: how wide a halo a chunk of the
// octree stages needs (specs/pipeline.md §15, "overlap and own"). Prepares the scan's points in
// core (frame, radii, normals, orientation, roughness; no outlier removal), runs the octree stages
// on all of them, then for every cell at level L holding at least N points runs the same stages on
// the points of the cell widened by a halo (1/64, 1/32, ... of the cell) and compares, inside the
// cell, the leaves after building and passive marking, after balance, after the closure, and the
// final corner values (distance and normal, bit for bit). Prints, per cell, the narrowest halo at
// which each of them first agrees; then, for chunk runs that mark what may differ from the whole
// run (halos 1/8, 1/4 and 1/2), the share of the cell's filled leaves they leave unmarked, or
// "all" when the check accepts the cell. --marked-only skips the search for agreement.
#include <fmt/core.h>

#include <cmath>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "io/readers.h"
#include "knn.h"
#include "stages.h"

namespace {

using iso::NodeKind;
using Leaves = std::map<std::pair<int, uint64_t>, NodeKind>;  // (level, key) → kind

// Whether the cell (nodeLevel, nodeKey) lies inside the cell (level, key).
bool isInside(int nodeLevel, uint64_t nodeKey, int level, uint64_t key) {
  return nodeLevel >= level && (nodeKey >> (3 * (nodeLevel - level))) == key;
}

// The leaves (filled or empty) inside the cell (level, key) of a tree.
Leaves leavesIn(const iso::Octree& tree, int level, uint64_t key) {
  Leaves out;
  for (const iso::OctreeNode& n : tree.nodes)
    if (n.kind != NodeKind::Internal && isInside(n.level, n.key, level, key))
      out[{n.level, n.key}] = n.kind;
  return out;
}

struct Run {
  std::unique_ptr<iso::PointIndex> index;
  iso::Octree tree;
  iso::Closure closure;
  Leaves built, balanced, closed;
  uint8_t maxLeafLevel = 0;  // before balance
};

Run runStages(const iso::PointSet& points, const iso::RadiusStats& radii, int level,
              uint64_t key, const iso::LoadedBox* box = nullptr) {
  Run r;
  r.index = std::make_unique<iso::PointIndex>(points.position);
  const iso::SdfEvaluator sdf(points, *r.index, iso::BuildOptions{}.smoothing,
                              iso::BuildOptions{}.fit, box);
  iso::CornerField corners;
  r.tree = iso::buildOctree(points, sdf, iso::BuildOptions{}, radii, corners);
  iso::markPassiveLeaves(r.tree, points);
  for (const iso::OctreeNode& n : r.tree.nodes)
    if (n.isFilled()) r.maxLeafLevel = std::max(r.maxLeafLevel, n.level);
  r.built = leavesIn(r.tree, level, key);
  iso::balanceOctree(r.tree, points);
  r.balanced = leavesIn(r.tree, level, key);
  r.closure = iso::sampleClosedSurface(r.tree, points, sdf, std::move(corners));
  r.closed = leavesIn(r.tree, level, key);
  return r;
}

// The share of the filled leaves inside the cell (level, key) that a chunk run leaves unmarked.
double unmarkedShare(const Run& r, int level, uint64_t key) {
  size_t filled = 0, unmarked = 0;
  for (uint32_t i = 0; i < r.tree.nodes.size(); ++i) {
    const iso::OctreeNode& n = r.tree.nodes[i];
    if (!n.isFilled() || !isInside(n.level, n.key, level, key)) continue;
    ++filled;
    unmarked += r.tree.isExact(i) ? 1 : 0;
  }
  return filled ? double(unmarked) / double(filled) : 1.0;
}

// The points of `all` inside the box [lo, hi] (their order kept).
iso::PointSet pointsIn(const iso::PointSet& all, const glm::dvec3& lo, const glm::dvec3& hi) {
  std::vector<uint32_t> keep;
  for (uint32_t i = 0; i < all.size(); ++i) {
    const glm::dvec3 p(all.position[i]);
    if (p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z)
      keep.push_back(i);
  }
  iso::PointSet out;
  const auto take = [&](auto& dst, const auto& src) {
    if (!src.empty())
      for (uint32_t i : keep) dst.push_back(src[i]);
  };
  take(out.position, all.position);
  take(out.normal, all.normal);
  take(out.color, all.color);
  take(out.weight, all.weight);
  take(out.radius, all.radius);
  take(out.roughness, all.roughness);
  take(out.key, all.key);
  return out;
}

// Corners of the filled leaves in `leaves` whose final values differ between two runs.
size_t differingCorners(const Leaves& leaves, const Run& a, const Run& b) {
  size_t differ = 0;
  for (const auto& [cell, kind] : leaves) {
    if (kind == NodeKind::Empty) continue;
    for (int c = 0; c < iso::kCorners; ++c) {
      const iso::GridPoint p = iso::cornerPoint(uint8_t(cell.first), cell.second, c);
      const iso::CornerSample& x = a.closure.corners.value[a.closure.corners.find(p)];
      const iso::CornerSample& y = b.closure.corners.value[b.closure.corners.find(p)];
      differ += x.distance != y.distance || x.normal != y.normal ? 1 : 0;
    }
  }
  return differ;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help") {
    fmt::print(stderr,
               "usage: iso-bench-halo SCAN [--level L (3)] [--min-points N (50000)] "
               "[--marked-only]\n");
    return argc < 2 ? 2 : 0;
  }
  int level = 3;
  size_t minPoints = 50000;
  bool markedOnly = false;  // skip the search for the narrowest agreeing halo
  for (int i = 2; i < argc; ++i) {
    const std::string option = argv[i];
    if (option == "--marked-only") markedOnly = true;
    else if (option == "--level" && i + 1 < argc) level = std::atoi(argv[++i]);
    else if (option == "--min-points" && i + 1 < argc)
      minPoints = std::strtoull(argv[++i], nullptr, 10);
    else {
      fmt::print(stderr, "iso-bench-halo: unknown option '{}'\n", option);
      return 2;
    }
  }
  if (level < 1 || level > 10) {
    fmt::print(stderr, "iso-bench-halo: --level must be 1 to 10\n");
    return 2;
  }
  const iso::PointCloud cloud = iso::readPointFile(argv[1]);
  const iso::Frame frame = iso::chooseFrame(cloud);
  iso::PointSet all = iso::makePointSet(cloud, frame);
  iso::sortByKey(all);
  iso::mergeDuplicates(all);
  const iso::BuildOptions options;
  iso::RadiusStats radii;
  {
    const iso::PointIndex index(all.position);
    const iso::Neighbors neighbors = iso::findNeighbors(all, index, options.neighbors);
    radii = iso::estimateRadii(all, neighbors);
    std::vector<uint8_t> estimated(all.size(), 0);
    for (size_t i = 0; i < all.size(); ++i)
      estimated[i] = all.normal.empty() || all.normal[i] == glm::vec3(0.0f);
    iso::estimateNormals(all, neighbors);
    iso::orientNormals(all, neighbors, options.orient, estimated, options.orientBlockPoints);
    iso::estimateRoughness(all, neighbors);
  }
  fmt::print("{}: {} points; cells of level {} with at least {} points\n", argv[1], all.size(),
             level, minPoints);
  const Run whole = runStages(all, radii, 0, 0);
  iso::CoarseCells coarse;  // what chunk runs know of all points
  iso::addCoarseCells(coarse, all, 0, all.size());
  float maxRadius = 0.0f;
  for (float r : all.radius) maxRadius = std::max(maxRadius, r);
  const auto within = [](const Leaves& leaves, int level, uint64_t key) {
    Leaves out;
    for (const auto& [cell, kind] : leaves)
      if (isInside(cell.first, cell.second, level, key)) out[cell] = kind;
    return out;
  };
  std::map<uint64_t, size_t> perCell;
  for (uint64_t key : all.key) ++perCell[key >> (3 * (iso::kMaxLevel - level))];
  const double cell = std::ldexp(1.0, -level);
  fmt::print("{:>10} {:>9} | narrowest halo, in cell edges, at which the chunk agrees | {:>9} |"
             " chunk run's unmarked filled leaves in the cell\n",
             "cell", "points", "loaded");
  fmt::print("{:>10} {:>9} | {:>9} {:>9} {:>9} {:>9} | {:>9} | {:>7} {:>7} {:>7}\n", "", "",
             "octree", "balance", "closure", "corners", "", "1/8", "1/4", "1/2");
  for (const auto& [key, count] : perCell) {
    if (count < minPoints) continue;
    const auto c = iso::mortonDecode(key);
    const glm::dvec3 lo = glm::dvec3(c[0], c[1], c[2]) * cell, hi = lo + cell;
    const Leaves built = within(whole.built, level, key);
    const Leaves balanced = within(whole.balanced, level, key);
    const Leaves closed = within(whole.closed, level, key);
    std::vector<std::string> first(4, markedOnly ? "-" : "> 1/2");
    size_t loaded = 0;
    for (int denominator = 64; !markedOnly && denominator >= 2; denominator /= 2) {
      const double halo = 1.0 / denominator;
      const iso::PointSet part = pointsIn(all, lo - halo * cell, hi + halo * cell);
      const Run r = runStages(part, radii, level, key);
      const bool agree[4] = {r.built == built, r.balanced == balanced, r.closed == closed,
                             r.closed == closed && differingCorners(closed, whole, r) == 0};
      for (int s = 0; s < 4; ++s)
        if (agree[s] && first[size_t(s)][0] == '>')
          first[size_t(s)] = fmt::format("1/{}", denominator);
      loaded = part.size();
      if (agree[3]) break;
    }
    // Chunk runs that mark what may differ (specs/pipeline.md §15): how much of the cell they
    // prove, and whether the check accepts it whole ("all").
    std::vector<std::string> proven;
    for (int denominator : {8, 4, 2}) {
      const double halo = 1.0 / denominator;
      iso::LoadedBox box;
      for (int a = 0; a < 3; ++a) {
        box.lo[a] = lo[a] - halo * cell <= 0.0 ? -HUGE_VAL : lo[a] - halo * cell;
        box.hi[a] = hi[a] + halo * cell >= 1.0 ? HUGE_VAL : hi[a] + halo * cell;
      }
      box.maxRadius = maxRadius;
      box.maxLeafLevel = whole.maxLeafLevel;
      box.fillPasses = uint8_t(whole.closure.passes - 1);
      box.ownLevel = uint8_t(level);
      box.ownKey = key;
      box.coarse = &coarse;
      const Run r = runStages(pointsIn(all, box.lo, box.hi), radii, level, key, &box);
      proven.push_back(iso::ownCellIsExact(r.tree, r.closure)
                           ? "all"
                           : fmt::format("{:.1f}%", 100.0 * unmarkedShare(r, level, key)));
    }
    fmt::print("{:>10} {:>9} | {:>9} {:>9} {:>9} {:>9} | {:>9} | {:>7} {:>7} {:>7}\n", key, count,
               first[0], first[1], first[2], first[3], loaded, proven[0], proven[1], proven[2]);
    std::fflush(stdout);
  }
  return 0;
}
