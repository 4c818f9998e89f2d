// The torus against its area formulas, an exhaustive (u, v) grid, and fine marching of its exact
// signed distance, with grazing rays whose answers are known in closed form.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>

#include "pipeline/geom/shape.h"
#include "tests/geom/shape_checks.h"

namespace iso {
namespace {

const glm::dvec3 kCenter(0.5, -1.0, 2.0);
constexpr double kMajor = 1.0, kMinor = 0.35;
constexpr double kPi = std::numbers::pi;

std::unique_ptr<Shape> torus() {
  return makeShape({.name = "torus", .center = kCenter, .radius = kMajor, .minorRadius = kMinor});
}

double torusDistance(const glm::dvec3& p) {
  const glm::dvec3 d = p - kCenter;
  return std::hypot(std::hypot(d.x, d.y) - kMajor, d.z) - kMinor;
}

// A dense (u, v) grid of surface points: the exhaustive search for closest points.
std::vector<glm::dvec3> surfaceGrid(int nu, int nv) {
  std::vector<glm::dvec3> points;
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      const double u = 2.0 * kPi * i / nu, v = 2.0 * kPi * j / nv;
      const double ring = kMajor + kMinor * std::cos(v);
      points.push_back(kCenter +
                       glm::dvec3(ring * std::cos(u), ring * std::sin(u), kMinor * std::sin(v)));
    }
  }
  return points;
}

TEST(Torus, areaBoundsAndClosednessMatchFormulas) {
  const auto t = torus();
  EXPECT_EQ(t->name(), "torus");
  EXPECT_DOUBLE_EQ(t->area(), 4.0 * kPi * kPi * kMajor * kMinor);
  EXPECT_TRUE(t->isClosed());
  EXPECT_EQ(t->boundsMin(), kCenter - glm::dvec3(kMajor + kMinor, kMajor + kMinor, kMinor));
  EXPECT_EQ(t->boundsMax(), kCenter + glm::dvec3(kMajor + kMinor, kMajor + kMinor, kMinor));
}

TEST(Torus, samplesLieOnSurfaceWithMatchingNormals) {
  test::expectSamplesOnSurface(*torus(), torusDistance, 20000, 1e-14);
}

// The outer half (ρ > R) holds ∫(R + r cos v) dv over |v| < π/2 of the area: 1/2 + r/(πR).
// Unweighted tube angles would give 1/2.
TEST(Torus, outerHalfHoldsItsExactAreaFraction) {
  constexpr int kSamples = 200000;
  int outer = 0;
  for (const glm::dvec3& p : test::samplePositions(*torus(), kSamples, 3))
    outer += std::hypot(p.x - kCenter.x, p.y - kCenter.y) > kMajor;
  const double expected = 0.5 + kMinor / (kPi * kMajor);
  const double sigma = std::sqrt(expected * (1.0 - expected) / kSamples);
  EXPECT_NEAR(double(outer) / kSamples, expected, 4.0 * sigma);
}

// Finer: bands of the tube angle v against their exact areas r ∫(R + r cos v) dv · 2π, and the
// angle u around the axis uniform.
TEST(Torus, tubeAndRingAnglesFollowTheAreaElement) {
  constexpr int kBins = 16, kSamples = 200000;
  std::vector<double> vCounts(kBins, 0.0), uCounts(kBins, 0.0), vExpected(kBins);
  for (const glm::dvec3& p : test::samplePositions(*torus(), kSamples, 4)) {
    const glm::dvec3 d = p - kCenter;
    const double v = std::atan2(d.z, std::hypot(d.x, d.y) - kMajor) + kPi;
    const double u = std::atan2(d.y, d.x) + kPi;
    vCounts[std::min(int(v / (2.0 * kPi) * kBins), kBins - 1)] += 1.0;
    uCounts[std::min(int(u / (2.0 * kPi) * kBins), kBins - 1)] += 1.0;
  }
  for (int i = 0; i < kBins; ++i) {
    // v measured from the inner equator (v + π): the element is R - r cos w.
    const double w0 = 2.0 * kPi * i / kBins, w1 = 2.0 * kPi * (i + 1) / kBins;
    const double band = kMajor * (w1 - w0) - kMinor * (std::sin(w1) - std::sin(w0));
    vExpected[i] = kSamples * band / (2.0 * kPi * kMajor);
  }
  // 15 degrees of freedom: P(chi² > 40) ≈ 5e-4.
  EXPECT_LT(test::chiSquare(vCounts, vExpected), 40.0);
  EXPECT_LT(test::chiSquare(uCounts, std::vector<double>(kBins, double(kSamples) / kBins)), 40.0);
}

TEST(Torus, closestPointMatchesBruteForce) {
  const auto t = torus();
  const std::vector<glm::dvec3> grid = surfaceGrid(720, 360);
  std::mt19937_64 rng(5);
  const glm::dvec3 extent(1.6, 1.6, 0.6);
  for (int i = 0; i < 60; ++i) {
    const glm::dvec3 q = test::randomPoint(rng, kCenter - extent, kCenter + extent);
    test::expectClosestIsExact(*t, torusDistance, q, grid, true);
  }
  // In the tube, in the hole, on the core circle, far away.
  for (const glm::dvec3 q : {glm::dvec3(1.1, 0.0, 0.05), glm::dvec3(0.2, 0.1, 0.0),
                             glm::dvec3(0.0, -1.0, 0.0), glm::dvec3(30.0, -7.0, 12.0)})
    test::expectClosestIsExact(*t, torusDistance, kCenter + q, grid, true);
}

TEST(Torus, queryOnTheAxisIsEquidistantFromTheCoreCircle) {
  const auto t = torus();
  for (double z : {0.0, 0.3, -2.0}) {
    const ClosestPoint c = t->closest(kCenter + glm::dvec3(0.0, 0.0, z));
    EXPECT_NEAR(c.distance, std::hypot(kMajor, z) - kMinor, 1e-15);
    EXPECT_NEAR(torusDistance(c.position), 0.0, 1e-15);
  }
  // On the core circle every point of its tube circle is equally near.
  const ClosestPoint core = t->closest(kCenter + glm::dvec3(0.0, kMajor, 0.0));
  EXPECT_NEAR(core.distance, kMinor, 1e-15);
  EXPECT_NEAR(torusDistance(core.position), 0.0, 1e-15);
}

TEST(Torus, rayIntersectionMatchesFineMarchingOfTheExactSdf) {
  const auto t = torus();
  std::mt19937_64 rng(7);
  const glm::dvec3 extent(2.0, 2.0, 1.0);
  int hits = 0;
  for (int i = 0; i < 400; ++i) {
    const glm::dvec3 o = test::randomPoint(rng, kCenter - extent, kCenter + extent);
    // Half of the rays aim near the surface, so that many graze it.
    glm::dvec3 d = test::randomDirection(rng);
    if (i % 2 == 0) d = t->sample(rng).position + 0.05 * test::randomDirection(rng) - o;
    const std::optional<double> expected = test::marchRay(torusDistance, o, d, 1e-9, 8.0, 2e-4);
    const std::optional<double> hit = t->intersect(o, d, 1e-9, 8.0);
    if (expected) {
      ASSERT_TRUE(hit) << "missed ray " << i;
      EXPECT_NEAR(*hit, *expected, 1e-12 * (1.0 + *expected)) << "ray " << i;
      ++hits;
    } else if (hit) {
      // Marching can step over a grazing hit; then it must be a true surface point.
      EXPECT_LE(std::abs(torusDistance(o + *hit * d)), 1e-12) << "ray " << i;
    }
  }
  EXPECT_GT(hits, 150);
}

// Vertical rays just inside the outer and inner equators, and a horizontal one just under the top
// of the tube, cut chords of length ~sqrt(δ): found, with the entry of the 2D circle equation.
TEST(Torus, grazingRaysFindTheirTinyChords) {
  const auto t = torus();
  for (double delta : {1e-4, 1e-8, 1e-12}) {
    for (double x : {kMajor + kMinor - delta, kMajor - kMinor + delta}) {
      const double w = x - kMajor;
      const double z = std::sqrt((kMinor - std::abs(w)) * (kMinor + std::abs(w)));
      const glm::dvec3 o = kCenter + glm::dvec3(x, 0.0, 2.0);
      const std::optional<double> hit = t->intersect(o, glm::dvec3(0.0, 0.0, -1.0), 0.0, 10.0);
      ASSERT_TRUE(hit) << "x = " << x;
      EXPECT_NEAR(*hit, 2.0 - z, 1e-9) << "x = " << x;
    }
    const glm::dvec3 o = kCenter + glm::dvec3(-3.0, kMajor, kMinor - delta);
    const std::optional<double> top = t->intersect(o, glm::dvec3(1.0, 0.0, 0.0), 0.0, 10.0);
    ASSERT_TRUE(top) << "delta = " << delta;
    const double rho = kMajor + std::sqrt(delta * (2.0 * kMinor - delta));  // entering at ρ > R
    EXPECT_NEAR(*top, 3.0 - std::sqrt(rho * rho - kMajor * kMajor), 1e-6);
  }
  // Just outside: a miss.
  EXPECT_FALSE(t->intersect(kCenter + glm::dvec3(kMajor + kMinor + 1e-9, 0.0, 2.0),
                            glm::dvec3(0.0, 0.0, -1.0), 0.0, 10.0));
}

TEST(Torus, rayFromInsideTheTubeFindsTheExitAndSkipsTMin) {
  const auto t = torus();
  const glm::dvec3 o = kCenter + glm::dvec3(kMajor, 0.0, 0.0);
  const glm::dvec3 d(3.0, 0.0, 0.0);  // not unit: t is in units of d
  EXPECT_NEAR(*t->intersect(o, d, 0.0, 10.0), kMinor / 3.0, 1e-15);
  // From the outer surface outwards the start itself is not a hit.
  const glm::dvec3 onSurface = kCenter + glm::dvec3(kMajor + kMinor, 0.0, 0.0);
  EXPECT_FALSE(t->intersect(onSurface, d, 0.0, 10.0));
  // Inwards from the same point: through the tube, the hole and the far tube.
  EXPECT_NEAR(*t->intersect(onSurface, -d, 0.0, 10.0), 2.0 * kMinor / 3.0, 1e-15);
  EXPECT_NEAR(*t->intersect(onSurface, -d, 2.0 * kMinor / 3.0 + 1e-9, 10.0), (2.0 * kMajor) / 3.0,
              1e-15);
  EXPECT_FALSE(t->intersect(o, d, kMinor / 3.0 + 1e-9, 10.0));
}

}  // namespace
}  // namespace iso
