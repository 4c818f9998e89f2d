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

// Whether the leaf's zero set lies mostly far from the points. It is sampled where it crosses
// lines along the axes, a 4×4 grid inside the leaf; a crossing is far when it lies farther than
// `reach` radii of influence from its nearest point, and the leaf is far when at least half its
// crossings are. Crossings on the leaf's 12 edges count too when they are near: a surface that
// only clips a corner of the leaf crosses its edges there, between the grid's lines; far ones
// there decide only a leaf whose surface misses the grid. The crossings are found first and their
// nearest points looked up until the answer is known.
bool isFarFromPoints(const OctreeNode& leaf, const std::array<double, 8>& f,
                     const SdfEvaluator& sdf, const PointSet& points, double reach) {
  const double size = std::ldexp(1.0, -leaf.level);
  const auto cell = mortonDecode(leaf.key);
  const glm::dvec3 origin = glm::dvec3(cell[0], cell[1], cell[2]) * size;
  constexpr int kGrid = 3 * kTrimLines * kTrimLines, kEdges = 12;
  std::array<glm::dvec3, kGrid> grid;
  std::array<glm::dvec3, kEdges> edges;
  int g = 0, e = 0;
  // The crossing along `axis` through (a, b) on the other two axes, if any, into `out`.
  const auto crossing = [&](int axis, double a, double b, glm::dvec3* out) {
    std::array<double, 3> lo{}, hi{};
    lo[size_t((axis + 1) % 3)] = hi[size_t((axis + 1) % 3)] = a;
    lo[size_t((axis + 2) % 3)] = hi[size_t((axis + 2) % 3)] = b;
    hi[size_t(axis)] = 1.0;
    const double f0 = trilinear(f, lo), f1 = trilinear(f, hi);
    if ((f0 < 0.0) == (f1 < 0.0) || f0 == f1) return false;
    std::array<double, 3> x = lo;
    x[size_t(axis)] = f0 / (f0 - f1);
    *out = origin + size * glm::dvec3(x[0], x[1], x[2]);
    return true;
  };
  for (int axis = 0; axis < 3; ++axis) {
    for (int i = 0; i < kTrimLines; ++i)
      for (int j = 0; j < kTrimLines; ++j)
        g += crossing(axis, (i + 0.5) / kTrimLines, (j + 0.5) / kTrimLines, &grid[size_t(g)]);
    for (int c = 0; c < 4; ++c) e += crossing(axis, c & 1, c >> 1, &edges[size_t(e)]);
  }
  const auto far = [&](const glm::dvec3& x) {
    float distance = 0.0f;
    const uint32_t nearest = sdf.nearest(x, distance);
    return double(distance) > reach * double(points.radius[nearest]);
  };
  int farGrid = 0;
  for (int i = 0; i < g; ++i) {
    farGrid += far(grid[size_t(i)]);
    // Near edge crossings only add to the count: too few far ones left to reach the share.
    if (double(farGrid + g - 1 - i) < kTrimShare * double(g)) return false;
  }
  int nearEdges = 0, farEdges = 0;
  for (int i = 0; i < e; ++i) (far(edges[size_t(i)]) ? farEdges : nearEdges) += 1;
  const int count = g + nearEdges;
  return count > 0 ? double(farGrid) >= kTrimShare * double(count) : farEdges > 0;
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
                      Closure& closure, double reach, const std::vector<uint32_t>* candidates) {
  const size_t count = candidates ? candidates->size() : tree.nodes.size();
  const auto nodeAt = [&](size_t i) { return candidates ? (*candidates)[i] : uint32_t(i); };
  std::vector<uint8_t> far(count, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 1024),
                    [&](const tbb::blocked_range<size_t>& r) {
                      spillPause();
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const OctreeNode& leaf = tree.nodes[nodeAt(i)];
                        if (!leaf.isFilled() || leaf.pointCount() > 0) continue;
                        std::array<double, 8> f{};
                        for (int c = 0; c < kCorners; ++c)
                          f[size_t(c)] = closure.corners.value[closure.corners.find(
                              cornerPoint(leaf.level, leaf.key, c))].distance;
                        far[i] = isFarFromPoints(leaf, f, sdf, points, reach);
                      }
                    });
  std::vector<uint32_t> emptied;
  for (size_t i = 0; i < far.size(); ++i)
    if (far[i]) {
      tree.nodes[nodeAt(i)].kind = NodeKind::Empty;
      emptied.push_back(nodeAt(i));
    }
  if (emptied.empty()) return 0;
  emptyBareInternalNodes(tree);
  // Corners of emptied leaves are no longer in use, and a corner that hung on an emptied leaf's
  // face keeps its value but no longer hangs.
  refreshCornersAround(tree, closure, emptied);
  return emptied.size();
}

}  // namespace iso
