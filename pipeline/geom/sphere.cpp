// Sphere: Archimedes' sampling, radial projection, and the numerically stable ray quadratic.
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>

#include "pipeline/geom/analytic.h"
#include "pipeline/geom/random.h"

namespace iso {
namespace {

class Sphere final : public Shape {
 public:
  Sphere(const glm::dvec3& center, double radius) : center_(center), radius_(radius) {}

  std::string name() const override { return "sphere"; }
  double area() const override { return 4.0 * std::numbers::pi * radius_ * radius_; }
  bool isClosed() const override { return true; }
  glm::dvec3 boundsMin() const override { return center_ - radius_; }
  glm::dvec3 boundsMax() const override { return center_ + radius_; }

  // Archimedes: z is uniform on [-1, 1] for area-uniform points. (1 - z)(1 + z) avoids the
  // cancellation of 1 - z² near the poles.
  SurfacePoint sample(std::mt19937_64& rng) const override {
    const double z = 1.0 - 2.0 * uniform01(rng);
    const double phi = 2.0 * std::numbers::pi * uniform01(rng);
    const double s = std::sqrt((1.0 - z) * (1.0 + z));
    const glm::dvec3 normal(s * std::cos(phi), s * std::sin(phi), z);
    return {center_ + radius_ * normal, normal};
  }

  // The centre itself is equally far from every point; it gets the north pole.
  ClosestPoint closest(const glm::dvec3& query) const override {
    const glm::dvec3 d = query - center_;
    const double length = std::sqrt(glm::dot(d, d));
    const glm::dvec3 normal = length > 0.0 ? d / length : glm::dvec3(0.0, 0.0, 1.0);
    return {center_ + radius_ * normal, normal, std::abs(length - radius_)};
  }

  // The discriminant b² - ac is formed as a(r² - |f - (b/a)d|²) from the centre's distance to the
  // line, and the roots as c/q and q/a with q = -(b + sign(b)√disc), which avoids both
  // cancellations (Haines, Günther and Akenine-Möller, "Precision Improvements for Ray/Sphere
  // Intersection", Ray Tracing Gems, 2019, ch. 7).
  std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                  double tMin, double tMax) const override {
    const glm::dvec3 f = origin - center_;
    const double a = glm::dot(direction, direction);
    if (!(a > 0.0)) return std::nullopt;
    const double b = glm::dot(f, direction);
    const glm::dvec3 offLine = f - (b / a) * direction;
    const double disc = a * (radius_ * radius_ - glm::dot(offLine, offLine));
    if (disc < 0.0) return std::nullopt;
    const double q = -(b + std::copysign(std::sqrt(disc), b));
    if (q == 0.0) return tMin < 0.0 && 0.0 < tMax ? std::optional<double>(0.0) : std::nullopt;
    const double c = glm::dot(f, f) - radius_ * radius_;
    const double t0 = std::min(c / q, q / a);
    const double t1 = std::max(c / q, q / a);
    if (t0 > tMin && t0 < tMax) return t0;
    if (t1 > tMin && t1 < tMax) return t1;
    return std::nullopt;
  }

 private:
  glm::dvec3 center_;
  double radius_;
};

}  // namespace

std::unique_ptr<Shape> makeSphere(const glm::dvec3& center, double radius) {
  return std::make_unique<Sphere>(center, radius);
}

}  // namespace iso
