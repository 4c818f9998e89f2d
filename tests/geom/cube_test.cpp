// The cube: equal faces, exact closest points at faces, edges and corners, and slab rays.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "pipeline/geom/shape.h"
#include "tests/geom/shape_checks.h"

namespace iso {
namespace {

const glm::dvec3 kCenter(-1.0, 2.0, 0.5);
constexpr double kHalf = 0.75;

std::unique_ptr<Shape> cube() {
  return makeShape({.name = "cube", .center = kCenter, .halfSize = kHalf});
}

// The box distance (Quílez): outside, the length of the positive part; inside, the largest
// (negative) coordinate.
double cubeDistance(const glm::dvec3& p) {
  const glm::dvec3 q = glm::abs(p - kCenter) - kHalf;
  return glm::length(glm::max(q, 0.0)) + std::min(std::max({q.x, q.y, q.z}), 0.0);
}

TEST(Cube, areaBoundsAndClosednessMatchFormulas) {
  const auto c = cube();
  EXPECT_EQ(c->name(), "cube");
  EXPECT_DOUBLE_EQ(c->area(), 24.0 * kHalf * kHalf);
  EXPECT_TRUE(c->isClosed());
  EXPECT_EQ(c->boundsMin(), kCenter - kHalf);
  EXPECT_EQ(c->boundsMax(), kCenter + kHalf);
}

TEST(Cube, samplesLieOnFacesWithFaceNormals) {
  const auto c = cube();
  test::expectSamplesOnSurface(*c, cubeDistance, 20000, 1e-15);
  std::mt19937_64 rng(2);
  for (int i = 0; i < 2000; ++i) {
    const SurfacePoint s = c->sample(rng);
    const glm::dvec3 d = (s.position - kCenter) / kHalf;
    // The normal is the axis of the coordinate at ±1.
    EXPECT_EQ(glm::dot(s.normal, d), 1.0);
  }
}

// Six faces of equal area, each cut into 3×3 cells: 54 cells of equal area.
TEST(Cube, samplesAreUniformOverFacesAndWithinThem) {
  constexpr int kSamples = 216000;
  std::vector<double> counts(54, 0.0);
  std::mt19937_64 rng(4);
  const auto c = cube();
  for (int i = 0; i < kSamples; ++i) {
    const SurfacePoint s = c->sample(rng);
    const int axis = s.normal.x != 0.0 ? 0 : s.normal.y != 0.0 ? 1 : 2;
    const int face = 2 * axis + (s.normal[axis] < 0.0);
    const glm::dvec3 u = (s.position - kCenter + kHalf) / (2.0 * kHalf);
    const int a = std::min(int(3.0 * u[(axis + 1) % 3]), 2);
    const int b = std::min(int(3.0 * u[(axis + 2) % 3]), 2);
    counts[face * 9 + a * 3 + b] += 1.0;
  }
  // 53 degrees of freedom: P(chi² > 95) ≈ 3e-4.
  EXPECT_LT(test::chiSquare(counts, std::vector<double>(54, kSamples / 54.0)), 95.0);
}

TEST(Cube, closestPointMatchesBruteForceInsideAndOutside) {
  const auto c = cube();
  const std::vector<glm::dvec3> surface = test::samplePositions(*c, 30000, 6);
  std::mt19937_64 rng(8);
  for (int i = 0; i < 200; ++i) {
    const glm::dvec3 q = test::randomPoint(rng, kCenter - 2.0 * kHalf, kCenter + 2.0 * kHalf);
    test::expectClosestIsExact(*c, cubeDistance, q, surface, false);
  }
}

TEST(Cube, insideQueriesGoToTheNearestFace) {
  const auto c = cube();
  const ClosestPoint p = c->closest(kCenter + glm::dvec3(0.1, -0.6, 0.3));
  EXPECT_EQ(p.position, kCenter + glm::dvec3(0.1, -kHalf, 0.3));
  EXPECT_EQ(p.normal, glm::dvec3(0.0, -1.0, 0.0));
  EXPECT_NEAR(p.distance, kHalf - 0.6, 1e-15);
}

TEST(Cube, outsideQueriesNearEdgesAndCornersPointAwayFromThem) {
  const auto c = cube();
  // Beyond one face: the face normal exactly.
  ClosestPoint p = c->closest(kCenter + glm::dvec3(0.2, 0.1, 2.0));
  EXPECT_EQ(p.normal, glm::dvec3(0.0, 0.0, 1.0));
  EXPECT_EQ(p.position, kCenter + glm::dvec3(0.2, 0.1, kHalf));
  // Beyond an edge.
  p = c->closest(kCenter + glm::dvec3(1.25, 0.3, -1.05));
  EXPECT_EQ(p.position, kCenter + glm::dvec3(kHalf, 0.3, -kHalf));
  EXPECT_NEAR(p.distance, std::hypot(0.5, 0.3), 1e-15);
  EXPECT_NEAR(glm::length(p.normal - glm::normalize(glm::dvec3(0.5, 0.0, -0.3))), 0.0, 1e-15);
  // Beyond a corner.
  p = c->closest(kCenter + glm::dvec3(-1.0, 1.75, 0.95));
  EXPECT_EQ(p.position, kCenter + glm::dvec3(-kHalf, kHalf, kHalf));
  EXPECT_NEAR(glm::length(p.normal - glm::normalize(glm::dvec3(-0.25, 1.0, 0.2))), 0.0, 1e-15);
}

TEST(Cube, rayIntersectionMatchesBruteForceMarching) {
  const auto c = cube();
  std::mt19937_64 rng(10);
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    const glm::dvec3 o = test::randomPoint(rng, kCenter - 2.0 * kHalf, kCenter + 2.0 * kHalf);
    // Half of the rays aim at the surface.
    glm::dvec3 d = 1.3 * test::randomDirection(rng);
    if (i % 2 == 0) d = c->sample(rng).position - o;
    const std::optional<double> expected = test::marchRay(cubeDistance, o, d, 0.0, 5.0, 1e-3);
    const std::optional<double> hit = c->intersect(o, d, 0.0, 5.0);
    ASSERT_EQ(hit.has_value(), expected.has_value()) << "ray " << i;
    if (!hit) continue;
    ++hits;
    EXPECT_NEAR(*hit, *expected, 1e-13) << "ray " << i;
  }
  EXPECT_GT(hits, 100);
}

TEST(Cube, raysThroughCornersAndAlongAxesHit) {
  const auto c = cube();
  // At a corner along the diagonal.
  const glm::dvec3 o = kCenter + glm::dvec3(2.0 * kHalf);
  EXPECT_NEAR(*c->intersect(o, glm::dvec3(-1.0), 0.0, 10.0), kHalf, 1e-15);
  // Along an axis from outside and from the centre (the exit).
  EXPECT_NEAR(
      *c->intersect(kCenter + glm::dvec3(0.0, 0.0, 3.0), glm::dvec3(0.0, 0.0, -1.0), 0.0, 10.0),
      3.0 - kHalf, 1e-15);
  EXPECT_NEAR(*c->intersect(kCenter, glm::dvec3(0.0, 2.0, 0.0), 0.0, 10.0), kHalf / 2.0, 1e-15);
  // Parallel to a face, outside its slab: a miss.
  EXPECT_FALSE(c->intersect(kCenter + glm::dvec3(-3.0, 0.0, kHalf + 1e-12),
                            glm::dvec3(1.0, 0.0, 0.0), 0.0, 10.0));
}

}  // namespace
}  // namespace iso
