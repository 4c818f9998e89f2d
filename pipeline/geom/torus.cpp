// Ring torus around the z axis: rejection sampling of the tube angle, closest point through the
// core circle, and ray intersection by safe stepping on the exact signed distance.
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <numbers>

#include "pipeline/geom/analytic.h"
#include "pipeline/geom/random.h"

namespace iso {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Rounding noise of the signed distance along a ray, in units of the scale (major radius plus the
// origin's distance): a point closer to the surface than this counts as on it.
constexpr double kOnSurface = 32.0 * std::numeric_limits<double>::epsilon();
// A safety net only: tangent rays pass in a few dozen steps (see safeStep), random rays in ~7.
constexpr int kMaxSteps = 10000;

// The signed distance f at a point, its derivative along the unit ray direction, and the radius of
// a ball around the point in which f is smooth with |f''| <= 1 / smoothRadius (see safeStep).
struct Probe {
  double distance;
  double slope;
  double smoothRadius;
};

// The largest step along the ray from a point where g = ±f >= 0 that cannot cross g = 0. Sphere
// tracing (Hart 1996) may always step g, since an exact distance is 1-Lipschitz. Near the surface
// the second derivative bound does better: in cylindrical coordinates the Hessian of the distance
// s to the core circle has eigenvalues 0, 1/s and cos(v)/ρ, so within half of min(s, ρ) of the
// point |g''| <= K = 1/smoothRadius, and g(h) >= g + g'h - Kh²/2 stays positive up to that
// quadratic's first root. Tangent rays then pass in a few dozen steps instead of creeping forever.
double safeStep(double g, double slope, double smoothRadius, double minStep) {
  const double g0 = std::max(g, 0.0);
  double step = g0;
  if (smoothRadius > 0.0) {
    const double curvature = 1.0 / smoothRadius;
    const double root = std::sqrt(slope * slope + 2.0 * curvature * g0);
    // The two forms of the first root avoid cancellation for either sign of the slope.
    const double quadratic = slope >= 0.0 ? (slope + root) / curvature : 2.0 * g0 / (root - slope);
    step = std::max(step, std::min(quadratic, smoothRadius));
  }
  return std::max(step, minStep);
}

class Torus final : public Shape {
 public:
  Torus(const glm::dvec3& center, double major, double minor)
      : center_(center), major_(major), minor_(minor) {}

  std::string name() const override { return "torus"; }
  double area() const override {
    return 4.0 * std::numbers::pi * std::numbers::pi * major_ * minor_;
  }
  bool isClosed() const override { return true; }
  glm::dvec3 boundsMin() const override { return center_ - extent(); }
  glm::dvec3 boundsMax() const override { return center_ + extent(); }

  // The area element is r (R + r cos v) du dv: u is uniform, and v is accepted with probability
  // (R + r cos v) / (R + r) (rejection sampling; at least half of the draws are accepted).
  SurfacePoint sample(std::mt19937_64& rng) const override {
    const double u = kTwoPi * uniform01(rng);
    double v = 0.0;
    do {
      v = kTwoPi * uniform01(rng);
    } while (uniform01(rng) * (major_ + minor_) >= major_ + minor_ * std::cos(v));
    const glm::dvec3 normal(std::cos(v) * std::cos(u), std::cos(v) * std::sin(u), std::sin(v));
    const double ring = major_ + minor_ * std::cos(v);
    return {center_ + glm::dvec3(ring * std::cos(u), ring * std::sin(u), minor_ * std::sin(v)),
            normal};
  }

  // Project the query onto the core circle, then onto the tube around that point. Every core point
  // is equally far from a query on the axis (it takes the +x one); a query on the core circle
  // takes the outward point of its tube circle.
  ClosestPoint closest(const glm::dvec3& query) const override {
    const glm::dvec3 d = query - center_;
    const double rho = std::sqrt(d.x * d.x + d.y * d.y);
    const double radialX = rho > 0.0 ? d.x / rho : 1.0;
    const double radialY = rho > 0.0 ? d.y / rho : 0.0;
    const double wr = rho - major_;
    const double s = std::sqrt(wr * wr + d.z * d.z);
    const double nr = s > 0.0 ? wr / s : 1.0;
    const double nz = s > 0.0 ? d.z / s : 0.0;
    const double ring = major_ + minor_ * nr;
    return {center_ + glm::dvec3(ring * radialX, ring * radialY, minor_ * nz),
            glm::dvec3(nr * radialX, nr * radialY, nz), std::abs(s - minor_)};
  }

  std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                  double tMin, double tMax) const override {
    const double speed = std::sqrt(glm::dot(direction, direction));
    if (!(speed > 0.0) || !std::isfinite(speed)) return std::nullopt;
    const glm::dvec3 o = origin - center_;
    const glm::dvec3 e = direction / speed;
    double enter = 0.0, exit = 0.0;
    if (!boundingSphereSpan(o, e, enter, exit)) return std::nullopt;
    const double from = std::max(tMin * speed, enter);
    const double to = std::min(tMax * speed, exit);
    const double tolerance = kOnSurface * (major_ + std::sqrt(glm::dot(o, o)));
    const std::optional<double> hit = march(o, e, from, to, tolerance);
    if (!hit) return std::nullopt;
    const double t = *hit / speed;
    if (t > tMin && t < tMax) return t;
    return std::nullopt;
  }

 private:
  glm::dvec3 extent() const { return {major_ + minor_, major_ + minor_, minor_}; }

  Probe probe(const glm::dvec3& p, const glm::dvec3& e) const {
    const double rho = std::sqrt(p.x * p.x + p.y * p.y);
    const double wr = rho - major_;
    const double s = std::sqrt(wr * wr + p.z * p.z);
    const double smoothRadius = 0.5 * std::min(rho, s);
    double slope = 0.0;
    if (smoothRadius > 0.0) slope = (wr / s) * (p.x * e.x + p.y * e.y) / rho + (p.z / s) * e.z;
    return {s - minor_, slope, smoothRadius};
  }

  // The span of a unit-direction ray inside a sphere slightly larger than the torus, so that the
  // march starts off the surface even when the ray starts far away or tMin is -infinity.
  bool boundingSphereSpan(const glm::dvec3& o, const glm::dvec3& e, double& enter,
                          double& exit) const {
    const double radius = (major_ + minor_) * (1.0 + 1e-6);
    const double b = glm::dot(o, e);
    const glm::dvec3 offLine = o - b * e;
    const double disc = radius * radius - glm::dot(offLine, offLine);
    if (disc < 0.0) return false;
    const double q = -(b + std::copysign(std::sqrt(disc), b));
    const double c = glm::dot(o, o) - radius * radius;
    enter = q != 0.0 ? std::min(c / q, q) : 0.0;
    exit = q != 0.0 ? std::max(c / q, q) : 0.0;
    return true;
  }

  // Step from `from` towards `to` until the signed distance reaches zero from the side the ray
  // starts on. A start on the surface counts as the side the ray moves into, so that the start
  // itself (outside the open interval) is not reported.
  std::optional<double> march(const glm::dvec3& o, const glm::dvec3& e, double from, double to,
                              double tolerance) const {
    double t = from;
    Probe p = probe(o + t * e, e);
    const bool startsOnSurface = std::abs(p.distance) <= tolerance;
    const double side = (startsOnSurface ? p.slope >= 0.0 : p.distance > 0.0) ? 1.0 : -1.0;
    for (int i = 0; i < kMaxSteps && t <= to; ++i) {
      const double g = side * p.distance;
      if (g <= tolerance && (i > 0 || !startsOnSurface)) return polish(o, e, t, p);
      t += safeStep(g, side * p.slope, p.smoothRadius, tolerance);
      p = probe(o + t * e, e);
    }
    return std::nullopt;
  }

  // Newton steps on the signed distance while they shrink it; the march ends within rounding noise
  // of the root already, so this only removes that last error where the ray is not tangent.
  double polish(const glm::dvec3& o, const glm::dvec3& e, double t, Probe p) const {
    for (int i = 0; i < 3 && p.slope != 0.0; ++i) {
      const double dt = -p.distance / p.slope;
      if (!(std::abs(dt) <= p.smoothRadius)) break;
      const Probe next = probe(o + (t + dt) * e, e);
      if (!(std::abs(next.distance) < std::abs(p.distance))) break;
      t += dt;
      p = next;
    }
    return t;
  }

  glm::dvec3 center_;
  double major_;
  double minor_;
};

}  // namespace

std::unique_ptr<Shape> makeTorus(const glm::dvec3& center, double majorRadius, double minorRadius) {
  return std::make_unique<Torus>(center, majorRadius, minorRadius);
}

}  // namespace iso
