// Axis-aligned cube with sharp edges: faces sampled uniformly, closest point by nearest face
// (inside) or clamping (outside), ray intersection by slabs.
#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>

#include "pipeline/geom/analytic.h"
#include "pipeline/geom/random.h"

namespace iso {
namespace {

glm::dvec3 axisVector(int axis, double sign) {
  glm::dvec3 v(0.0);
  v[axis] = sign;
  return v;
}

class Cube final : public Shape {
 public:
  Cube(const glm::dvec3& center, double halfSize) : center_(center), half_(halfSize) {}

  std::string name() const override { return "cube"; }
  double area() const override { return 24.0 * half_ * half_; }
  bool isClosed() const override { return true; }
  glm::dvec3 boundsMin() const override { return center_ - half_; }
  glm::dvec3 boundsMax() const override { return center_ + half_; }

  // Faces have equal areas: pick one uniformly, then a uniform point on it.
  SurfacePoint sample(std::mt19937_64& rng) const override {
    const int face = std::min(int(6.0 * uniform01(rng)), 5);
    const int axis = face / 2;
    const double sign = face % 2 == 0 ? 1.0 : -1.0;
    glm::dvec3 p;
    p[axis] = sign * half_;
    p[(axis + 1) % 3] = half_ * (2.0 * uniform01(rng) - 1.0);
    p[(axis + 2) % 3] = half_ * (2.0 * uniform01(rng) - 1.0);
    return {center_ + p, axisVector(axis, sign)};
  }

  ClosestPoint closest(const glm::dvec3& query) const override {
    const glm::dvec3 d = query - center_;
    const glm::dvec3 clamped = glm::clamp(d, -half_, half_);
    if (clamped == d) return closestFromInside(d);
    // Outside: the clamped point. Only the clamped coordinates differ from the query, so the
    // normal is exactly the face normal when one is clamped, and points from the edge or vertex
    // to the query otherwise.
    const glm::dvec3 away = d - clamped;
    const double distance = std::sqrt(glm::dot(away, away));
    return {center_ + clamped, away / distance, distance};
  }

  std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                  double tMin, double tMax) const override {
    const glm::dvec3 o = origin - center_;
    double enter = -std::numeric_limits<double>::infinity();
    double exit = std::numeric_limits<double>::infinity();
    for (int axis = 0; axis < 3; ++axis) {
      if (direction[axis] == 0.0) {
        if (std::abs(o[axis]) > half_) return std::nullopt;
        continue;
      }
      const double t0 = (-half_ - o[axis]) / direction[axis];
      const double t1 = (half_ - o[axis]) / direction[axis];
      enter = std::max(enter, std::min(t0, t1));
      exit = std::min(exit, std::max(t0, t1));
    }
    if (!(enter <= exit)) return std::nullopt;
    // The surface is met where the ray enters the solid and where it leaves it.
    if (enter > tMin && enter < tMax) return enter;
    if (exit > tMin && exit < tMax) return exit;
    return std::nullopt;
  }

 private:
  // Inside (or on the surface): the nearest face, the first of equally near ones.
  ClosestPoint closestFromInside(const glm::dvec3& d) const {
    int axis = 0;
    for (int i = 1; i < 3; ++i)
      if (std::abs(d[i]) > std::abs(d[axis])) axis = i;
    const double sign = d[axis] >= 0.0 ? 1.0 : -1.0;
    glm::dvec3 p = d;
    p[axis] = sign * half_;
    return {center_ + p, axisVector(axis, sign), half_ - std::abs(d[axis])};
  }

  glm::dvec3 center_;
  double half_;
};

}  // namespace

std::unique_ptr<Shape> makeCube(const glm::dvec3& center, double halfSize) {
  return std::make_unique<Cube>(center, halfSize);
}

}  // namespace iso
