// Closing the surface (specs/pipeline.md, "Closure"): passive leaves follow the points' disks, but
// the zero set of the patches can run past them, most at sharp edges, whose reconstruction is
// rounded inward, into empty cells. A ray that enters such a region would cross no zero set and
// leak into the empty inside. So every empty cell into which a filled leaf's zero set runs through
// a shared face is filled, when the zero set crosses that face within the radius of influence of a
// point (so open boundaries do not grow without end); the new leaves are balanced and sampled, and
// the pass repeats until nothing is left to fill. A leaf that holds points but no zero set (its
// estimate displaced, where sampling is sparse) gets its neighbour across the face nearest to the
// zero set filled the same way.
#include <algorithm>
#include <cmath>
#include <glm/vec3.hpp>

#include "pipeline/base/collect.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr uint8_t kMaxClosurePasses = 8;  // passes at most: a bound on the work

using Distances = std::array<float, kCorners>;  // at a leaf's corners, in corner order

// A square on a face of a filled leaf: its corners in cyclic order (grid units) and the leaf's
// signed distance there.
struct FaceSquare {
  std::array<glm::dvec3, 4> corner;
  std::array<double, 4> value{};
};

// The part of face (axis, side) of the leaf that the cell (level, key) at or below the leaf's
// level across that face shares with it, with the leaf's patch (bilinear on the face) there.
FaceSquare faceSquare(const Distances& f, const OctreeNode& leaf, int axis, int side, uint8_t level,
                      uint64_t key) {
  const auto leafCell = mortonDecode(leaf.key);
  const auto cell = mortonDecode(key);
  const double leafSize = std::ldexp(1.0, kMaxLevel - leaf.level);
  const double size = std::ldexp(1.0, kMaxLevel - level);
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  FaceSquare out;
  const std::array<std::array<int, 2>, 4> cycle = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
  for (size_t i = 0; i < 4; ++i) {
    glm::dvec3 p;
    p[axis] = (double(leafCell[size_t(axis)]) + side) * leafSize;
    p[u] = (double(cell[size_t(u)]) + cycle[i][0]) * size;
    p[v] = (double(cell[size_t(v)]) + cycle[i][1]) * size;
    out.corner[i] = p;
    std::array<double, 3> local{};
    for (int a = 0; a < 3; ++a) local[size_t(a)] = p[a] / leafSize - double(leafCell[size_t(a)]);
    std::array<double, 8> values{};
    for (int c = 0; c < kCorners; ++c) values[size_t(c)] = f[size_t(c)];
    out.value[i] = trilinear(values, local);
  }
  return out;
}

// A point where the leaf's zero set crosses the square near the points (within the radius of
// influence of the nearest one), if there is one: the crossings along its 4 edges are tried.
bool crossesNearPoints(const FaceSquare& square, const SdfEvaluator& sdf, const PointSet& points) {
  const double unit = std::ldexp(1.0, -kMaxLevel);
  for (size_t e = 0; e < 4; ++e) {
    const double fa = square.value[e], fb = square.value[(e + 1) % 4];
    if ((fa < 0.0) == (fb < 0.0)) continue;
    const double t = fa / (fa - fb);
    const glm::dvec3& a = square.corner[e];
    const glm::dvec3& b = square.corner[(e + 1) % 4];
    const glm::dvec3 x = (a + t * (b - a)) * unit;
    float distance = 0.0f;
    const uint32_t nearest = sdf.nearest(x, distance);
    if (distance <= points.radius[nearest]) return true;
  }
  return false;
}

// The face of a leaf whose corners are nearest the zero set (smallest mean |f|).
int faceTowardSurface(const Distances& f) {
  int best = 0;
  double bestMean = 1e300;
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2, side = face % 2;
    double sum = 0.0;
    for (int c = 0; c < kCorners; ++c)
      if (((c >> axis) & 1) == side) sum += std::abs(f[size_t(c)]);
    if (sum < bestMean) {
      bestMean = sum;
      best = face;
    }
  }
  return best;
}

bool hasSurface(const Distances& f) {
  int negative = 0;
  for (float d : f) negative += d < 0.0f ? 1 : 0;
  return negative != 0 && negative != kCorners;
}

// An empty cell the surface runs into.
struct Exit {
  uint8_t level;
  uint64_t key;
  auto operator<=>(const Exit&) const = default;
};

// The empty cells below the internal node `across` (a finer neighbour of the leaf across its face
// (axis, side)) that touch the face and into which the leaf's zero set runs near the points.
void finerExits(const Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                const Distances& f, const OctreeNode& leaf, int axis, int side, uint32_t across,
                std::vector<Exit>& out) {
  const OctreeNode& node = tree.nodes[across];
  for (int octant = 0; octant < 8; ++octant) {
    if (((octant >> axis) & 1) != (side ? 0 : 1)) continue;  // not on the shared face
    const uint32_t child = node.firstChild + uint32_t(octant);
    const OctreeNode& c = tree.nodes[child];
    if (c.kind == NodeKind::Internal) {
      finerExits(tree, points, sdf, f, leaf, axis, side, child, out);
    } else if (c.kind == NodeKind::Empty &&
               crossesNearPoints(faceSquare(f, leaf, axis, side, c.level, c.key), sdf, points)) {
      out.push_back({c.level, c.key});
    }
  }
}

// The empty cells the surface runs into from one leaf.
void exitsOf(const Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
             const CornerField& field, uint32_t id, std::vector<Exit>& out) {
  const OctreeNode& leaf = tree.nodes[id];
  if (!leaf.isFilled()) return;
  Distances f{};
  for (int c = 0; c < kCorners; ++c)
    f[size_t(c)] = field.value[field.find(cornerPoint(leaf.level, leaf.key, c))].distance;
  const auto cell = mortonDecode(leaf.key);
  const bool lost = leaf.pointCount() > 0 && !hasSurface(f);
  const int toward = lost ? faceTowardSurface(f) : -1;
  std::array<double, 8> values{};
  for (int c = 0; c < kCorners; ++c) values[size_t(c)] = f[size_t(c)];
  // Whether the patch changes sign on the face: where its 4 corners agree, the bilinear (a convex
  // combination of them) agrees everywhere on it, and no part of the face has a crossing.
  const auto changesSign = [&](int axis, int side) {
    int negative = 0;
    for (int i = 0; i < 4; ++i) {
      std::array<double, 3> local{};
      local[size_t(axis)] = side;
      local[size_t((axis + 1) % 3)] = i & 1;
      local[size_t((axis + 2) % 3)] = i >> 1;
      negative += trilinear(values, local) < 0.0;
    }
    return negative != 0 && negative != 4;
  };
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2, side = face % 2;
    if (face != toward && !changesSign(axis, side)) continue;
    std::array<int64_t, 3> n = {cell[0], cell[1], cell[2]};
    n[size_t(axis)] += side ? 1 : -1;
    if (n[size_t(axis)] < 0 || n[size_t(axis)] >= (int64_t{1} << leaf.level)) continue;
    const uint64_t key = mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2]));
    const uint32_t across = tree.find(leaf.level, key);
    if (tree.nodes[across].kind == NodeKind::Internal) {
      // Finer cells across the face: the empty ones the zero set runs into through their part
      // of it (without this, a coarse leaf's surface could run into the empty child of a finer
      // neighbour).
      finerExits(tree, points, sdf, f, leaf, axis, side, across, out);
      continue;
    }
    if (tree.nodes[across].kind != NodeKind::Empty) continue;
    // The zero set runs out through this face near the points, or the leaf holds points but no
    // zero set (a displaced estimate) and this face is the nearest to it.
    if (face == toward ||
        crossesNearPoints(faceSquare(f, leaf, axis, side, leaf.level, key), sdf, points))
      out.push_back({leaf.level, key});
  }
}

// Fill the empty cells the surface runs into from the given leaves; returns the filled cells.
// The cells are found in parallel on the tree as it stands and filled coarsest first, in key
// order, so the result does not depend on the order of the leaves.
std::vector<uint32_t> fillExits(Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                                const CornerField& field, const std::vector<uint32_t>& leaves,
                                const ExitFilter& accept = {}) {
  std::vector<Exit> targets =
      collectInParallel<Exit>(leaves.size(), 1024, [&](size_t i, std::vector<Exit>& out) {
        const size_t before = out.size();
        exitsOf(tree, points, sdf, field, leaves[i], out);
        if (!accept) return;
        const OctreeNode& leaf = tree.nodes[leaves[i]];
        out.erase(std::remove_if(
                      out.begin() + ptrdiff_t(before), out.end(),
                      [&](const Exit& e) { return !accept(leaf.level, leaf.key, e.level, e.key); }),
                  out.end());
      });
  std::sort(targets.begin(), targets.end());
  targets.erase(std::unique(targets.begin(), targets.end()), targets.end());
  std::vector<uint32_t> filled;
  for (const auto& [level, key] : targets) {
    const uint32_t node = tree.materialize(level, key, points);
    if (tree.nodes[node].kind != NodeKind::Empty) continue;  // inside a cell filled before
    tree.nodes[node].kind = NodeKind::Passive;
    filled.push_back(node);
  }
  return filled;
}

// Fill the exits of the given leaves, then of the leaves each pass adds, until none is left;
// then (with `refresh`) set the corner levels from the final leaves and snap the hanging corners.
void closeFrom(std::vector<uint32_t> fresh, Octree& tree, const PointSet& points,
               const SdfEvaluator& sdf, Closure& closure, const ExitFilter& firstPass = {},
               bool refresh = true) {
  addLeafCorners(closure.corners, tree, fresh, sdf);
  // Exits are found on the values as they are: snapping moves hanging corners very little.
  for (closure.passes = 1; closure.passes <= kMaxClosurePasses; ++closure.passes) {
    std::vector<uint32_t> filled = fillExits(tree, points, sdf, closure.corners, fresh,
                                             closure.passes == 1 ? firstPass : ExitFilter{});
    if (filled.empty()) break;
    closure.filled += filled.size();
    std::vector<uint32_t> created;
    balanceAfter(tree, points, filled, created);
    fresh = std::move(filled);
    fresh.insert(fresh.end(), created.begin(), created.end());
    addLeafCorners(closure.corners, tree, fresh, sdf);
  }
  // Splits left corners of leaves that are leaves no more.
  if (refresh) refreshCorners(tree, closure);
}

}  // namespace

void refreshCorners(const Octree& tree, Closure& closure) {
  closure.cornersInUse = refreshCornerLevels(closure.corners, tree);
  closure.hanging = findHangingCorners(tree, closure.corners);
  snapHangingCorners(closure.corners, closure.hanging);
}

Closure sampleClosedSurface(Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                            CornerField&& corners) {
  Closure closure;
  closure.corners = std::move(corners);
  std::vector<uint32_t> filled;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].isFilled()) filled.push_back(i);
  closeFrom(std::move(filled), tree, points, sdf, closure);
  return closure;
}

void closeFromLeaves(std::vector<uint32_t> leaves, Octree& tree, const PointSet& points,
                     const SdfEvaluator& sdf, Closure& closure, const ExitFilter& firstPass) {
  closeFrom(std::move(leaves), tree, points, sdf, closure, firstPass, false);
}

void closeAgain(Octree& tree, const PointSet& points, const SdfEvaluator& sdf, Closure& closure,
                const std::vector<uint8_t>& wasNegative) {
  // The filled leaves using a corner whose sign changed, found from those corners (few).
  std::vector<uint32_t> changed;
  const CornerField& field = closure.corners;
  for (uint32_t e = 0; e < wasNegative.size(); ++e) {
    if (wasNegative[e] == uint8_t(field.value[e].distance < 0.0f)) continue;
    std::array<uint32_t, 8> leaves{};
    const size_t count = filledLeavesAt(tree, field.point(e), leaves);
    changed.insert(changed.end(), leaves.begin(), leaves.begin() + ptrdiff_t(count));
  }
  std::sort(changed.begin(), changed.end());
  changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
  const std::vector<uint8_t> wasFilled = filledNodes(tree);
  const size_t before = closure.filled;
  closeFrom(std::move(changed), tree, points, sdf, closure, {}, false);
  closure.refilled = closure.filled - before;
  // The levels and hanging corners were up to date (the corner fit moves values only): they
  // change where the passes filled or split leaves.
  refreshCornersAround(tree, closure, nodesChangedSince(tree, wasFilled));
}

}  // namespace iso
