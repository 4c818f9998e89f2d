// Chunk runs of the octree stages (specs/pipeline.md §15): run on the points of a box around a
// cell, the stages mark every node and corner value that may differ from the run on all points.
// What they leave unmarked must be as in the run on all points, bit for bit; and an own cell the
// check accepts must come out whole as in the run on all points.
#include <gtest/gtest.h>

#include <array>
#include <map>
#include <memory>

#include "knn.h"
#include "pipeline_support.h"
#include "stages.h"

namespace iso {
namespace {

struct Prepared {
  PointSet points;
  RadiusStats radii;
};

// The point stages in core (no outlier removal).
Prepared prepare(const PointCloud& cloud) {
  Prepared p;
  p.points = makePointSet(cloud, chooseFrame(cloud));
  sortByKey(p.points);
  mergeDuplicates(p.points);
  const BuildOptions options;
  const PointIndex index(p.points.position);
  const Neighbors neighbors = findNeighbors(p.points, index, options.neighbors);
  p.radii = estimateRadii(p.points, neighbors);
  std::vector<uint8_t> estimated(p.points.size(), 0);
  for (size_t i = 0; i < p.points.size(); ++i)
    estimated[i] = p.points.normal.empty() || p.points.normal[i] == glm::vec3(0.0f);
  estimateNormals(p.points, neighbors);
  orientNormals(p.points, neighbors, options.orient, estimated, 4096);
  estimateRoughness(p.points, neighbors);
  return p;
}

struct StageRun {
  PointSet points;
  std::unique_ptr<PointIndex> index;
  Octree tree;
  Closure closure;
  uint8_t maxLeafLevel = 0;  // before balance
};

// Nodes of more than 64 points subdivide untested (4,096 by default): the level-2 cells of these
// scans are then many tested nodes across, as the chunks of a large scan are.
BuildOptions chunkedOptions() {
  BuildOptions options;
  options.maxTestedPoints = 64;
  return options;
}

// The octree stages up to the snapped corners, on all points (box null) or in a chunk run.
void runStages(StageRun& r, const RadiusStats& radii, const LoadedBox* box) {
  const BuildOptions options = chunkedOptions();
  r.index = std::make_unique<PointIndex>(r.points.position);
  const SdfEvaluator sdf(r.points, *r.index, options.smoothing, options.fit, box);
  CornerField corners;
  r.tree = buildOctree(r.points, sdf, options, radii, corners);
  markPassiveLeaves(r.tree, r.points);
  for (const OctreeNode& n : r.tree.nodes)
    if (n.isFilled()) r.maxLeafLevel = std::max(r.maxLeafLevel, n.level);
  balanceOctree(r.tree, r.points);
  r.closure = sampleClosedSurface(r.tree, r.points, sdf, std::move(corners));
}

bool isInside(uint8_t nodeLevel, uint64_t nodeKey, uint8_t level, uint64_t key) {
  return nodeLevel >= level && (nodeKey >> (3 * (nodeLevel - level))) == key;
}

// What a cell of a run holds: its leaves and the final values of their corners.
struct CellContent {
  std::map<std::pair<uint8_t, uint64_t>, NodeKind> leaves;
  std::map<std::pair<uint64_t, uint64_t>, std::tuple<float, glm::vec3, glm::vec3, uint8_t>> corners;
  bool operator==(const CellContent&) const = default;
};

CellContent contentOf(const StageRun& r, uint8_t level, uint64_t key) {
  CellContent out;
  const CornerField& field = r.closure.corners;
  for (const OctreeNode& n : r.tree.nodes) {
    if (n.kind == NodeKind::Internal || !isInside(n.level, n.key, level, key)) continue;
    // Filled leaves only: the tree is the paths to them (every internal node of a run on all
    // points has a filled leaf below it; a chunk run may split empty nodes further).
    if (!n.isFilled()) continue;
    out.leaves[{n.level, n.key}] = n.kind;
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(n.level, n.key, c);
      const uint32_t e = field.find(p);
      const CornerSample& v = field.value[e];
      out.corners[{gridKey(p).a, gridKey(p).b}] = {v.distance, v.normal, v.color,
                                                   field.coarsestLevel[e]};
    }
  }
  return out;
}

PointSet pointsIn(const PointSet& all, const LoadedBox& box) {
  PointSet out;
  for (size_t i = 0; i < all.size(); ++i) {
    const glm::dvec3 p(all.position[i]);
    if (p.x < box.lo.x || p.y < box.lo.y || p.z < box.lo.z || p.x > box.hi.x || p.y > box.hi.y ||
        p.z > box.hi.z)
      continue;
    out.position.push_back(all.position[i]);
    out.normal.push_back(all.normal[i]);
    out.weight.push_back(all.weight[i]);
    out.radius.push_back(all.radius[i]);
    out.roughness.push_back(all.roughness[i]);
    out.key.push_back(all.key[i]);
  }
  return out;
}

// The box of a cell widened by `halo` cell edges; faces on the frame cube's faces at infinity.
LoadedBox boxAround(uint8_t level, uint64_t key, double halo) {
  LoadedBox box;
  const auto c = mortonDecode(key);
  const double size = std::ldexp(1.0, -level);
  for (int a = 0; a < 3; ++a) {
    const double lo = c[size_t(a)] * size - halo * size,
                 hi = (c[size_t(a)] + 1) * size + halo * size;
    box.lo[a] = lo <= 0.0 ? -HUGE_VAL : lo;
    box.hi[a] = hi >= 1.0 ? HUGE_VAL : hi;
  }
  box.ownLevel = level;
  box.ownKey = key;
  return box;
}

// Node by node: whatever a chunk run leaves unmarked is as in the run on all points.
struct Audit {
  size_t exactLeaves = 0, exactCorners = 0;  // checked against the run on all points
  size_t differing = 0;                      // leaves that differ (all must be marked)
  size_t errors = 0;                         // unmarked, yet different
};

bool exactAround(const Octree& tree, const GridPoint& p) {
  const int64_t cells = int64_t{1} << kMaxLevel;
  for (int o = 0; o < 8; ++o) {
    const std::array<int64_t, 3> c = {int64_t(p.x) - (o & 1), int64_t(p.y) - ((o >> 1) & 1),
                                      int64_t(p.z) - ((o >> 2) & 1)};
    if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] >= cells || c[1] >= cells || c[2] >= cells)
      continue;
    if (!tree.isExact(
            tree.find(kMaxLevel, mortonEncode(uint32_t(c[0]), uint32_t(c[1]), uint32_t(c[2])))))
      return false;
  }
  return true;
}

Audit audit(const StageRun& chunk, const StageRun& whole) {
  Audit a;
  const CornerField &field = chunk.closure.corners, &wholeField = whole.closure.corners;
  std::vector<uint8_t> hanging(field.size(), 0);
  for (const HangingCorner& h : chunk.closure.hanging) hanging[h.corner] = 1;
  for (uint32_t i = 0; i < chunk.tree.nodes.size(); ++i) {
    const OctreeNode& n = chunk.tree.nodes[i];
    if (n.kind == NodeKind::Internal) continue;
    const OctreeNode& w = whole.tree.nodes[whole.tree.find(n.level, n.key)];
    // A chunk run may split empty nodes that the run on all points leaves whole.
    const bool same = n.isFilled() ? w.level == n.level && w.kind == n.kind
                                   : w.kind == NodeKind::Empty;
    const bool exact = chunk.tree.isExact(i);
    if (!same) {
      ++a.differing;
      if (exact) {
        ++a.errors;
        ADD_FAILURE() << "unmarked node differs: level " << int(n.level) << " key " << n.key;
      }
      continue;
    }
    if (!exact || !n.isFilled()) continue;
    ++a.exactLeaves;
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(n.level, n.key, c);
      const uint32_t e = field.find(p);
      // An unmarked value, not snapped, with unmarked leaves around it (its level and whether
      // it hangs come from them).
      if (field.inexact[e] || hanging[e] || !exactAround(chunk.tree, p)) continue;
      ++a.exactCorners;
      const uint32_t we = wholeField.find(p);
      const CornerSample &x = field.value[e], &y = wholeField.value[we];
      if (x.distance != y.distance || x.normal != y.normal || x.color != y.color ||
          field.coarsestLevel[e] != wholeField.coarsestLevel[we]) {
        ++a.errors;
        ADD_FAILURE() << "unmarked corner differs at " << p.x << " " << p.y << " " << p.z;
      }
    }
  }
  return a;
}

TEST(ChunkRun, whatAChunkRunLeavesUnmarkedIsAsInTheRunOnAllPoints) {
  // A noisy torus without normals (orientation, sharp curvature) and a cube (sharp edges, where
  // the closure fills cells).
  for (const char* shape : {"torus", "cube"}) {
    SCOPED_TRACE(shape);
    const Prepared prepared = prepare(test::scanOf(shape, 200000, false, 0.3, 7));
    StageRun whole;
    whole.points = prepared.points;
    runStages(whole, prepared.radii, nullptr);
    float maxRadius = 0.0f;
    for (float r : prepared.points.radius) maxRadius = std::max(maxRadius, r);
    CoarseCells coarse;
    addCoarseCells(coarse, prepared.points, 0, prepared.points.size());

    constexpr uint8_t kLevel = 2;
    std::map<uint64_t, size_t> perCell;
    for (uint64_t k : prepared.points.key) ++perCell[k >> (3 * (kMaxLevel - kLevel))];
    Audit total;
    size_t runs = 0, accepted = 0, acceptedDiffering = 0;
    for (const auto& [key, count] : perCell) {
      if (count < 3000) continue;
      // The chunk runs split the cell's ancestors: the run on all points must too.
      ASSERT_GT(prepared.points.size(), chunkedOptions().maxTestedPoints);
      for (uint8_t l = 1; l < kLevel; ++l)
        ASSERT_GT(coarse.pointsIn(l, key >> (3 * (kLevel - l))), chunkedOptions().maxTestedPoints);
      const CellContent expected = contentOf(whole, kLevel, key);
      for (double halo : {1.0 / 16, 1.0 / 4}) {
        LoadedBox box = boxAround(kLevel, key, halo);
        box.maxRadius = maxRadius;
        box.maxLeafLevel = whole.maxLeafLevel;
        box.fillPasses = uint8_t(whole.closure.passes - 1);
        box.coarse = &coarse;
        StageRun chunk;
        chunk.points = pointsIn(prepared.points, box);
        runStages(chunk, prepared.radii, &box);
        const Audit a = audit(chunk, whole);
        total.exactLeaves += a.exactLeaves;
        total.exactCorners += a.exactCorners;
        total.differing += a.differing;
        total.errors += a.errors;
        ++runs;
        const bool ok = ownCellIsExact(chunk.tree, chunk.closure);
        accepted += ok;
        if (ok && !(contentOf(chunk, kLevel, key) == expected)) {
          ++acceptedDiffering;
          ADD_FAILURE() << "cell " << key << " accepted at halo " << halo << " but differs";
        }
      }
    }
    std::printf("%s: %zu chunk runs; unmarked leaves %zu and corners %zu as in the whole run, "
                "%zu leaves differ (all marked); %zu own cells accepted\n",
                shape, runs, total.exactLeaves, total.exactCorners, total.differing, accepted);
    EXPECT_GE(runs, 8u);
    EXPECT_EQ(total.errors, 0u);
    EXPECT_EQ(acceptedDiffering, 0u);
    // Not vacuous: much is left unmarked, and much differs (so the marks are needed).
    EXPECT_GT(total.exactLeaves, 1000u);
    EXPECT_GT(total.exactCorners, 1000u);
    EXPECT_GT(total.differing, 100u);
  }
}

}  // namespace
}  // namespace iso
