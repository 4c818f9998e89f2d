// The sphere against Archimedes' theorem, its distance function and brute-force ray marching.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>

#include "pipeline/geom/shape.h"
#include "tests/geom/shape_checks.h"

namespace iso {
namespace {

const glm::dvec3 kCenter(3.0, -2.0, 5.0);
constexpr double kRadius = 2.5;

std::unique_ptr<Shape> sphere() {
  return makeShape({.name = "sphere", .center = kCenter, .radius = kRadius});
}

double sphereDistance(const glm::dvec3& p) { return glm::length(p - kCenter) - kRadius; }

TEST(Sphere, areaBoundsAndClosednessMatchFormulas) {
  const auto s = sphere();
  EXPECT_EQ(s->name(), "sphere");
  EXPECT_DOUBLE_EQ(s->area(), 4.0 * std::numbers::pi * kRadius * kRadius);
  EXPECT_TRUE(s->isClosed());
  EXPECT_EQ(s->boundsMin(), kCenter - kRadius);
  EXPECT_EQ(s->boundsMax(), kCenter + kRadius);
}

TEST(Sphere, samplesLieOnSurfaceWithRadialNormals) {
  const auto s = sphere();
  test::expectSamplesOnSurface(*s, sphereDistance, 20000, 1e-14 * kRadius);
  std::mt19937_64 rng(3);
  for (int i = 0; i < 1000; ++i) {
    const SurfacePoint p = s->sample(rng);
    EXPECT_GT(glm::dot(p.normal, (p.position - kCenter) / kRadius), 1.0 - 1e-14);
  }
}

// Archimedes: bands of equal height have equal areas, so z must be uniform.
TEST(Sphere, samplesAreAreaUniformAcrossEqualAreaZBands) {
  const auto s = sphere();
  constexpr int kBands = 20, kSamples = 200000;
  std::vector<double> counts(kBands, 0.0);
  for (const glm::dvec3& p : test::samplePositions(*s, kSamples, 5)) {
    const double u = (p.z - kCenter.z + kRadius) / (2.0 * kRadius);
    counts[std::min(int(u * kBands), kBands - 1)] += 1.0;
  }
  // 19 degrees of freedom: P(chi² > 45) ≈ 7e-4. Sampling the polar angle uniformly gives ~10⁴.
  EXPECT_LT(test::chiSquare(counts, std::vector<double>(kBands, double(kSamples) / kBands)), 45.0);
}

TEST(Sphere, closestPointMatchesBruteForceInsideAndOutside) {
  const auto s = sphere();
  const std::vector<glm::dvec3> surface = test::samplePositions(*s, 20000, 7);
  std::mt19937_64 rng(9);
  for (int i = 0; i < 200; ++i) {
    const glm::dvec3 q = test::randomPoint(rng, kCenter - 2.0 * kRadius, kCenter + 2.0 * kRadius);
    test::expectClosestIsExact(*s, sphereDistance, q, surface, true);
  }
  const ClosestPoint c = s->closest(kCenter);
  EXPECT_DOUBLE_EQ(c.distance, kRadius);
  EXPECT_DOUBLE_EQ(glm::length(c.position - kCenter), kRadius);
}

TEST(Sphere, rayIntersectionMatchesBruteForceMarching) {
  const auto s = sphere();
  std::mt19937_64 rng(11);
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    const glm::dvec3 o = test::randomPoint(rng, kCenter - 2.0 * kRadius, kCenter + 2.0 * kRadius);
    // Half of the rays aim at the surface.
    glm::dvec3 d = 0.7 * test::randomDirection(rng);
    if (i % 2 == 0) d = s->sample(rng).position - o;
    const std::optional<double> expected = test::marchRay(sphereDistance, o, d, 0.0, 20.0, 1e-3);
    const std::optional<double> hit = s->intersect(o, d, 0.0, 20.0);
    ASSERT_EQ(hit.has_value(), expected.has_value()) << "ray " << i;
    if (!hit) continue;
    ++hits;
    EXPECT_NEAR(*hit, *expected, 1e-12 * (1.0 + *expected));
  }
  EXPECT_GT(hits, 100);
}

TEST(Sphere, rayFromFarAwayIsExactAndRespectsTheInterval) {
  const auto s = sphere();
  const glm::dvec3 o = kCenter + glm::dvec3(1e5, 0.3, 0.2);
  const glm::dvec3 d(-2.0, 0.0, 0.0);
  const double entry = (1e5 - std::sqrt(kRadius * kRadius - 0.13)) / 2.0;
  const double exit = (1e5 + std::sqrt(kRadius * kRadius - 0.13)) / 2.0;
  EXPECT_NEAR(*s->intersect(o, d, 0.0, 1e6), entry, 1e-15 * 1e5);
  EXPECT_NEAR(*s->intersect(o, d, entry + 1e-6, 1e6), exit, 1e-15 * 1e5);
  EXPECT_FALSE(s->intersect(o, d, 0.0, entry - 1e-6));
  EXPECT_FALSE(s->intersect(o, -d, 0.0, 1e6));
  // Just past the silhouette: no hit.
  EXPECT_FALSE(s->intersect(kCenter + glm::dvec3(-10.0, kRadius * (1.0 + 1e-12), 0.0),
                            glm::dvec3(1.0, 0.0, 0.0), 0.0, 100.0));
}

}  // namespace
}  // namespace iso
