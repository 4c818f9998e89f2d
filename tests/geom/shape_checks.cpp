#include "tests/geom/shape_checks.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "pipeline/geom/random.h"

namespace iso::test {

glm::dvec3 randomDirection(std::mt19937_64& rng) {
  const glm::dvec3 g(standardNormal(rng), standardNormal(rng), standardNormal(rng));
  return glm::normalize(g);
}

glm::dvec3 randomPoint(std::mt19937_64& rng, const glm::dvec3& lower, const glm::dvec3& upper) {
  const glm::dvec3 u(uniform01(rng), uniform01(rng), uniform01(rng));
  return lower + u * (upper - lower);
}

void expectSamplesOnSurface(const Shape& shape, const SignedDistance& sdf, int count,
                            double tolerance, uint64_t seed) {
  std::mt19937_64 rng(seed);
  for (int i = 0; i < count; ++i) {
    const SurfacePoint s = shape.sample(rng);
    ASSERT_LE(std::abs(sdf(s.position)), tolerance) << "sample " << i;
    ASSERT_NEAR(glm::length(s.normal), 1.0, 1e-14);
    const ClosestPoint c = shape.closest(s.position);
    ASSERT_LE(c.distance, tolerance) << "sample " << i;
    ASSERT_GT(glm::dot(c.normal, s.normal), 1.0 - 1e-12) << "sample " << i;
  }
}

void expectClosestIsExact(const Shape& shape, const SignedDistance& sdf, const glm::dvec3& query,
                          const std::vector<glm::dvec3>& surface, bool isSmooth) {
  const ClosestPoint c = shape.closest(query);
  const double scale = 1.0 + glm::length(query);
  SCOPED_TRACE(testing::Message() << "query " << query.x << " " << query.y << " " << query.z);
  EXPECT_LE(std::abs(sdf(c.position)), 1e-13 * scale);
  EXPECT_NEAR(c.distance, glm::length(query - c.position), 1e-13 * scale);
  EXPECT_NEAR(c.distance, std::abs(sdf(query)), 1e-12 * scale);
  EXPECT_NEAR(glm::length(c.normal), 1.0, 1e-14);
  double nearestSample = std::numeric_limits<double>::infinity();
  for (const glm::dvec3& p : surface)
    nearestSample = std::min(nearestSample, glm::length(query - p));
  EXPECT_LE(c.distance, nearestSample + 1e-13 * scale);
  if (isSmooth && c.distance > 1e-9) {
    const glm::dvec3 along = (query - c.position) / c.distance;
    EXPECT_GT(std::abs(glm::dot(along, c.normal)), 1.0 - 1e-12);
  }
}

std::optional<double> marchRay(const SignedDistance& sdf, const glm::dvec3& origin,
                               const glm::dvec3& direction, double tMin, double tMax, double step) {
  double t0 = tMin;
  double f0 = sdf(origin + t0 * direction);
  while (t0 < tMax) {
    const double t1 = std::min(t0 + step, tMax);
    const double f1 = sdf(origin + t1 * direction);
    if ((f0 > 0.0) != (f1 > 0.0)) {
      double lo = t0, hi = t1;
      while (true) {
        const double mid = 0.5 * (lo + hi);
        if (mid <= lo || mid >= hi) break;
        if ((sdf(origin + mid * direction) > 0.0) == (f0 > 0.0))
          lo = mid;
        else
          hi = mid;
      }
      return hi;
    }
    t0 = t1;
    f0 = f1;
  }
  return std::nullopt;
}

double chiSquare(const std::vector<double>& observed, const std::vector<double>& expected) {
  double sum = 0.0;
  for (size_t i = 0; i < observed.size(); ++i)
    sum += (observed[i] - expected[i]) * (observed[i] - expected[i]) / expected[i];
  return sum;
}

std::vector<glm::dvec3> samplePositions(const Shape& shape, int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<glm::dvec3> positions(count);
  for (glm::dvec3& p : positions) p = shape.sample(rng).position;
  return positions;
}

}  // namespace iso::test
