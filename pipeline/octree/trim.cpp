// A surface that ends where the points end (specs/pipeline.md, "Trimming"): a filled leaf without
// points whose zero set lies mostly farther than a radius of influence from every point is
// emptied. Such sheets span holes in the scan (passive leaves and closure follow the points'
// disks, but balance splits and the patches beside a hole carry the zero set across it), and they
// are the largest errors of a conversion: the scene models only what its points show. The zero set
// of a leaf is sampled where it crosses a grid of lines along each axis, the leaf's edges among
// them (the trilinear is linear along them, so each crossing is exact). Leaves are emptied all at
// once from the tree as it stands, so the result does not depend on their order; internal nodes
// left with no filled descendant become empty, so that no level of detail draws what the finest
// level does not.
#include <tbb/parallel_for.h>

#include <cmath>
#include <optional>

#include "pipeline/base/buffers.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"

namespace iso {
namespace {

constexpr int kTrimLines = 4;  // lines per leaf edge along each axis
// A leaf is emptied when at least this share of its crossings is far: a leaf on the rim of a hole
// has its near crossings on the rim and the rest across the hole (specs/pipeline.md measures 1,
// 0.5 and 0.25).
constexpr double kTrimShare = 0.5;

// The crossings of the leaf's zero set with lines along the axes, a 4×4 grid inside the leaf:
// how many, and how many of them lie farther than `reach` radii of influence from their nearest
// point. Crossings on the leaf's 12 edges count too when they are near: a surface that only clips
// a corner of the leaf crosses its edges there, between the grid's lines. Far crossings on the
// edges are counted apart: they decide a leaf whose surface misses the grid.
struct Crossings {
  int count = 0, far = 0, farOnEdges = 0;
  bool isFar() const {
    return count > 0 ? double(far) >= kTrimShare * double(count) : farOnEdges > 0;
  }
};
Crossings zeroSetCrossings(const OctreeNode& leaf, const std::array<double, 8>& f,
                           const SdfEvaluator& sdf, const PointSet& points, double reach) {
  const double size = std::ldexp(1.0, -leaf.level);
  const auto cell = mortonDecode(leaf.key);
  const glm::dvec3 origin = glm::dvec3(cell[0], cell[1], cell[2]) * size;
  // The crossing along `axis` through (a, b) on the other two axes, if any: whether it is far.
  const auto crossing = [&](int axis, double a, double b) -> std::optional<bool> {
    std::array<double, 3> lo{}, hi{};
    lo[size_t((axis + 1) % 3)] = hi[size_t((axis + 1) % 3)] = a;
    lo[size_t((axis + 2) % 3)] = hi[size_t((axis + 2) % 3)] = b;
    hi[size_t(axis)] = 1.0;
    const double f0 = trilinear(f, lo), f1 = trilinear(f, hi);
    if ((f0 < 0.0) == (f1 < 0.0) || f0 == f1) return std::nullopt;
    std::array<double, 3> x = lo;
    x[size_t(axis)] = f0 / (f0 - f1);
    float distance = 0.0f;
    const uint32_t nearest = sdf.nearest(origin + size * glm::dvec3(x[0], x[1], x[2]), distance);
    return double(distance) > reach * double(points.radius[nearest]);
  };
  Crossings out;
  for (int axis = 0; axis < 3; ++axis) {
    for (int i = 0; i < kTrimLines; ++i)
      for (int j = 0; j < kTrimLines; ++j)
        if (const std::optional<bool> far =
                crossing(axis, (i + 0.5) / kTrimLines, (j + 0.5) / kTrimLines)) {
          ++out.count;
          out.far += *far;
        }
    for (int e = 0; e < 4; ++e)
      if (const std::optional<bool> far = crossing(axis, e & 1, e >> 1)) {
        out.count += !*far;
        out.farOnEdges += *far;
      }
  }
  return out;
}

// Empty the internal nodes none of whose descendants is filled (children come after parents).
void emptyBareInternalNodes(Octree& tree) {
  for (size_t i = tree.nodes.size(); i-- > 0;) {
    OctreeNode& node = tree.nodes[i];
    if (node.kind != NodeKind::Internal) continue;
    bool any = false;
    for (uint32_t c = 0; c < 8 && !any; ++c)
      any = tree.nodes[node.firstChild + c].kind != NodeKind::Empty;
    if (!any) node.kind = NodeKind::Empty;
  }
}

}  // namespace

size_t trimFarSurface(Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                      Closure& closure, double reach) {
  std::vector<uint8_t> far(tree.nodes.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, tree.nodes.size(), 1024),
                    [&](const tbb::blocked_range<size_t>& r) {
                      spillPause();
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const OctreeNode& leaf = tree.nodes[i];
                        if (!leaf.isFilled() || leaf.pointCount() > 0) continue;
                        std::array<double, 8> f{};
                        for (int c = 0; c < kCorners; ++c)
                          f[size_t(c)] = closure.corners.value[closure.corners.find(
                              cornerPoint(leaf.level, leaf.key, c))].distance;
                        const Crossings c = zeroSetCrossings(leaf, f, sdf, points, reach);
                        far[i] = c.isFar();
                      }
                    });
  size_t trimmed = 0;
  for (size_t i = 0; i < far.size(); ++i)
    if (far[i]) {
      tree.nodes[i].kind = NodeKind::Empty;
      ++trimmed;
    }
  if (trimmed == 0) return 0;
  emptyBareInternalNodes(tree);
  // Corners of emptied leaves are no longer in use, and a corner that hung on an emptied leaf's
  // face keeps its value but no longer hangs.
  closure.cornersInUse = refreshCornerLevels(closure.corners, tree);
  closure.hanging = findHangingCorners(tree, closure.corners);
  snapHangingCorners(closure.corners, closure.hanging);
  return trimmed;
}

}  // namespace iso
