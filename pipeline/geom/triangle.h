// Exact queries against one triangle, for the mesh shape's inner loops (inline on purpose: they run
// millions of times per second from the hierarchy traversal).
#pragma once

#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <optional>
#include <utility>

namespace iso {

// The point of triangle abc closest to p, by Voronoi regions of the vertices, edges and face
// (Ericson, Real-Time Collision Detection, 2005, section 5.1.5). The triangle must have a non-zero
// area; every branch returns a point of the triangle, so results are continuous across regions.
inline glm::dvec3 closestPointOnTriangle(const glm::dvec3& p, const glm::dvec3& a,
                                         const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0)
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denominator = 1.0 / (va + vb + vc);
  return a + ab * (vb * denominator) + ac * (vc * denominator);
}

// A ray prepared for the watertight ray/triangle test (Woop, Benthin and Wald, "Watertight
// Ray/Triangle Intersection", JCGT 2(1), 2013): the axis permutation that makes z the dominant
// direction and the shear that maps the ray onto +z. The direction need not be unit.
struct ShearedRay {
  glm::dvec3 origin;
  int kx, ky, kz;
  double sx, sy, sz;

  ShearedRay(const glm::dvec3& o, const glm::dvec3& d) : origin(o) {
    const glm::dvec3 m = glm::abs(d);
    kz = m.x >= m.y ? (m.x >= m.z ? 0 : 2) : (m.y >= m.z ? 1 : 2);
    kx = (kz + 1) % 3;
    ky = (kx + 1) % 3;
    if (d[kz] < 0.0) std::swap(kx, ky);  // keep the winding of the projected triangle
    sx = d[kx] / d[kz];
    sy = d[ky] / d[kz];
    sz = 1.0 / d[kz];
  }
};

// The ray parameter t in (tMin, tMax) where the ray meets triangle abc (either side), if any. Rays
// through a shared edge or vertex hit at least one of the triangles sharing it: the edge functions
// are the same products for both, and exact zeros are recomputed in extended precision.
inline std::optional<double> intersectTriangle(const ShearedRay& ray, const glm::dvec3& a,
                                               const glm::dvec3& b, const glm::dvec3& c,
                                               double tMin, double tMax) {
  const glm::dvec3 A = a - ray.origin, B = b - ray.origin, C = c - ray.origin;
  const double ax = A[ray.kx] - ray.sx * A[ray.kz], ay = A[ray.ky] - ray.sy * A[ray.kz];
  const double bx = B[ray.kx] - ray.sx * B[ray.kz], by = B[ray.ky] - ray.sy * B[ray.kz];
  const double cx = C[ray.kx] - ray.sx * C[ray.kz], cy = C[ray.ky] - ray.sy * C[ray.kz];
  double u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
  if (u == 0.0 || v == 0.0 || w == 0.0) {
    using Long = long double;
    u = double(Long(cx) * Long(by) - Long(cy) * Long(bx));
    v = double(Long(ax) * Long(cy) - Long(ay) * Long(cx));
    w = double(Long(bx) * Long(ay) - Long(by) * Long(ax));
  }
  if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return std::nullopt;
  const double det = u + v + w;
  if (det == 0.0) return std::nullopt;
  const double t = (u * ray.sz * A[ray.kz] + v * ray.sz * B[ray.kz] + w * ray.sz * C[ray.kz]) / det;
  if (t > tMin && t < tMax) return t;
  return std::nullopt;
}

}  // namespace iso
