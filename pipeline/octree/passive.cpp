// Passive leaves (specs/pipeline.md, "Passive leaves"): an empty octant is filled when the disk of
// influence of some point (centre p_i, normal n_i, radius r_i) touches its box, so that the
// surface between samples has leaves to live in and rays do not leak through holes.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>

#include "pipeline/base/buffers.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

// Distance from p to the convex polygon (given unordered, in the plane through p).
double distanceToPolygon(const glm::dvec3& p, const glm::dvec3& normal,
                         std::vector<glm::dvec3>& vertices) {
  glm::dvec3 centroid(0.0);
  for (const auto& v : vertices) centroid += v;
  centroid /= double(vertices.size());
  const glm::dvec3 t1 =
      glm::normalize(std::abs(normal.x) < 0.9 ? glm::cross(normal, glm::dvec3(1, 0, 0))
                                              : glm::cross(normal, glm::dvec3(0, 1, 0)));
  const glm::dvec3 t2 = glm::cross(normal, t1);
  std::sort(vertices.begin(), vertices.end(), [&](const glm::dvec3& a, const glm::dvec3& b) {
    return std::atan2(glm::dot(a - centroid, t2), glm::dot(a - centroid, t1)) <
           std::atan2(glm::dot(b - centroid, t2), glm::dot(b - centroid, t1));
  });
  bool inside = vertices.size() >= 3;
  double best = 1e300;
  for (size_t i = 0; i < vertices.size(); ++i) {
    const glm::dvec3& a = vertices[i];
    const glm::dvec3& b = vertices[(i + 1) % vertices.size()];
    const glm::dvec3 edge = b - a;
    const double length2 = glm::dot(edge, edge);
    const double t = length2 > 0.0 ? std::clamp(glm::dot(p - a, edge) / length2, 0.0, 1.0) : 0.0;
    best = std::min(best, glm::length(p - (a + t * edge)));
    if (glm::dot(glm::cross(edge, p - a), normal) < 0.0) inside = false;
  }
  return inside ? 0.0 : best;
}

}  // namespace

bool diskTouchesBox(const PointSet& points, uint32_t i, const glm::dvec3& lo,
                    const glm::dvec3& hi) {
  const glm::dvec3 p(points.position[i]);
  const double r = points.radius[i];
  if (glm::length(glm::max(glm::max(lo - p, p - hi), glm::dvec3(0.0))) > r) return false;
  const glm::dvec3 n(points.normal[i]);
  if (glm::dot(n, n) == 0.0) return true;  // no orientation: a ball
  const glm::dvec3 center = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  if (std::abs(glm::dot(center - p, n)) > glm::dot(half, glm::abs(n)))
    return false;  // plane misses
  // The polygon where the plane cuts the box: crossings of the 12 edges.
  std::vector<glm::dvec3> polygon;
  for (int axis = 0; axis < 3; ++axis)
    for (int e = 0; e < 4; ++e) {
      glm::dvec3 a = lo;
      a[(axis + 1) % 3] = (e & 1) ? hi[(axis + 1) % 3] : lo[(axis + 1) % 3];
      a[(axis + 2) % 3] = (e & 2) ? hi[(axis + 2) % 3] : lo[(axis + 2) % 3];
      glm::dvec3 b = a;
      b[axis] = hi[axis];
      const double da = glm::dot(a - p, n), db = glm::dot(b - p, n);
      if ((da < 0.0) == (db < 0.0) && da != 0.0) continue;
      polygon.push_back(da == db ? a : a + (b - a) * (da / (da - db)));
    }
  if (polygon.empty()) return false;
  return distanceToPolygon(p, n, polygon) <= r;
}

bool isCoveredByDisk(const Octree& tree, const PointSet& points, uint32_t node) {
  const OctreeNode& n = tree.nodes[node];
  const auto cell = mortonDecode(n.key);
  const double size = std::ldexp(1.0, -n.level);
  const glm::dvec3 lo = glm::dvec3(cell[0], cell[1], cell[2]) * size, hi = lo + size;
  return tree.anyPointNear(lo, hi, points,
                           [&](uint32_t i) { return diskTouchesBox(points, i, lo, hi); });
}

size_t markPassiveLeaves(Octree& tree, const PointSet& points, uint8_t minLevel) {
  std::vector<uint32_t> empty;
  for (const OctreeNode& node : tree.nodes)
    if (node.kind == NodeKind::Internal && node.level + 1 >= minLevel)
      for (uint32_t c = 0; c < 8; ++c)
        if (tree.nodes[node.firstChild + c].kind == NodeKind::Empty)
          empty.push_back(node.firstChild + c);
  std::vector<uint8_t> covered(empty.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, empty.size(), 64),
                    [&](const tbb::blocked_range<size_t>& r) {
                      spillPause();
                      for (size_t i = r.begin(); i < r.end(); ++i)
                        covered[i] = isCoveredByDisk(tree, points, empty[i]);
                    });
  size_t count = 0;
  for (size_t i = 0; i < empty.size(); ++i)
    if (covered[i]) {
      tree.nodes[empty[i]].kind = NodeKind::Passive;
      ++count;
    }
  return count;
}

}  // namespace iso
