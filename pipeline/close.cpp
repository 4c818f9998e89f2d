// Closing the surface (specs/pipeline.md, "Closure"): passive leaves follow the points' disks, but
// the zero set of the patches can run past them, most at sharp edges, whose reconstruction is
// rounded inward, into empty cells. A ray that enters such a region would cross no zero set and
// leak into the empty inside. So every empty cell into which a filled leaf's zero set runs through
// a shared face is filled, when it lies within reach of the points (its centre at most the nearest
// point's radius plus half its diagonal away, so open boundaries do not grow without end); the
// new leaves are balanced and sampled, and the pass repeats until nothing is left to fill.
#include <cmath>

#include "stages.h"

namespace iso {
namespace {

constexpr size_t kMaxPasses = 8;

// Whether the zero set of a filled leaf's patch crosses the face (axis, side).
bool crossesFace(const CornerField& field, const OctreeNode& leaf, int axis, int side) {
  bool positive = false, negative = false;
  for (int c = 0; c < kCorners; ++c) {
    if (((c >> axis) & 1) != side) continue;
    const float f = field.value[field.find(cornerPoint(leaf.level, leaf.key, c))].distance;
    positive = positive || f >= 0.0f;
    negative = negative || f < 0.0f;
  }
  return positive && negative;
}

// Make the cell (level, key) a node of the tree, splitting empty ancestors; returns it.
uint32_t materialize(Octree& tree, const PointSet& points, uint8_t level, uint64_t key) {
  for (;;) {
    const uint32_t node = tree.find(level, key);
    if (tree.nodes[node].level == level || tree.nodes[node].kind != NodeKind::Empty) return node;
    tree.split(node, points);  // an empty node: its children are empty too
  }
}

bool isNearPoints(const SdfEvaluator& sdf, const PointSet& points, uint8_t level, uint64_t key) {
  const auto c = mortonDecode(key);
  const double size = std::ldexp(1.0, -level);
  float distance = 0.0f;
  const uint32_t nearest = sdf.nearest((glm::dvec3(c[0], c[1], c[2]) + 0.5) * size, distance);
  return distance <= points.radius[nearest] + 0.5 * std::sqrt(3.0) * size;
}

// Fill the empty cells the surface runs into; returns how many.
size_t fillExits(Octree& tree, const PointSet& points, const SdfEvaluator& sdf, const CornerField& field) {
  std::vector<std::pair<uint8_t, uint64_t>> targets;
  for (const OctreeNode& leaf : tree.nodes) {
    if (!leaf.isFilled()) continue;
    const auto cell = mortonDecode(leaf.key);
    for (int face = 0; face < 6; ++face) {
      const int axis = face / 2, side = face % 2;
      std::array<int64_t, 3> n = {cell[0], cell[1], cell[2]};
      n[size_t(axis)] += side ? 1 : -1;
      if (n[size_t(axis)] < 0 || n[size_t(axis)] >= (int64_t{1} << leaf.level)) continue;
      const uint64_t key = mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2]));
      if (tree.nodes[tree.find(leaf.level, key)].kind != NodeKind::Empty) continue;
      if (!crossesFace(field, leaf, axis, side) || !isNearPoints(sdf, points, leaf.level, key)) continue;
      targets.push_back({leaf.level, key});
    }
  }
  size_t filled = 0;
  for (const auto& [level, key] : targets) {
    const uint32_t node = materialize(tree, points, level, key);
    if (tree.nodes[node].kind != NodeKind::Empty) continue;  // filled by an earlier target
    tree.nodes[node].kind = NodeKind::Passive;
    ++filled;
  }
  return filled;
}

}  // namespace

Closure sampleClosedSurface(Octree& tree, const PointSet& points, const SdfEvaluator& sdf, CornerCache& cache) {
  Closure closure;
  for (;;) {
    closure.corners = sampleLeafCorners(tree, sdf, cache);
    closure.hanging = findHangingCorners(tree, closure.corners);
    snapHangingCorners(closure.corners, closure.hanging);
    ++closure.passes;
    if (closure.passes > kMaxPasses) break;
    const size_t filled = fillExits(tree, points, sdf, closure.corners);
    if (filled == 0) break;
    closure.filled += filled;
    balanceOctree(tree, points);
  }
  return closure;
}

}  // namespace iso
