// The open shapes: the plane and the two facing sheets.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>

#include "pipeline/geom/shape.h"
#include "tests/geom/shape_checks.h"

namespace iso {
namespace {

const glm::dvec3 kCenter(10.0, -5.0, 1.0);
constexpr double kHalf = 1.5, kGap = 0.02;

std::unique_ptr<Shape> plane() {
  return makeShape({.name = "plane", .center = kCenter, .halfSize = kHalf});
}
std::unique_ptr<Shape> sheets() {
  return makeShape({.name = "sheets", .center = kCenter, .halfSize = kHalf, .gap = kGap});
}

// Distance to the square at height z (relative to the centre), clamped in x and y.
double squareDistance(const glm::dvec3& p, double z) {
  const glm::dvec3 d = p - kCenter;
  const double x = std::max(std::abs(d.x) - kHalf, 0.0), y = std::max(std::abs(d.y) - kHalf, 0.0);
  return std::sqrt(x * x + y * y + (d.z - z) * (d.z - z));
}

double sheetsDistance(const glm::dvec3& p) {
  return std::min(squareDistance(p, kGap / 2), squareDistance(p, -kGap / 2));
}

TEST(Plane, areaBoundsAndOpennessMatchTheSquare) {
  const auto p = plane();
  EXPECT_EQ(p->name(), "plane");
  EXPECT_DOUBLE_EQ(p->area(), 4.0 * kHalf * kHalf);
  EXPECT_FALSE(p->isClosed());
  EXPECT_EQ(p->boundsMin(), kCenter + glm::dvec3(-kHalf, -kHalf, 0.0));
  EXPECT_EQ(p->boundsMax(), kCenter + glm::dvec3(kHalf, kHalf, 0.0));
}

TEST(Plane, samplesLieOnTheSquareFacingUp) {
  const auto p = plane();
  test::expectSamplesOnSurface(
      *p, [](const glm::dvec3& q) { return squareDistance(q, 0.0); }, 10000, 0.0);
  std::mt19937_64 rng(1);
  for (int i = 0; i < 100; ++i) EXPECT_EQ(p->sample(rng).normal, glm::dvec3(0.0, 0.0, 1.0));
}

TEST(Plane, closestPointClampsToTheSquareAndKeepsItsNormal) {
  const auto p = plane();
  const std::vector<glm::dvec3> surface = test::samplePositions(*p, 20000, 3);
  std::mt19937_64 rng(5);
  const auto distance = [](const glm::dvec3& q) { return squareDistance(q, 0.0); };
  for (int i = 0; i < 100; ++i) {
    const glm::dvec3 q = test::randomPoint(rng, kCenter - 2.5, kCenter + 2.5);
    test::expectClosestIsExact(*p, distance, q, surface, false);
    EXPECT_EQ(p->closest(q).normal, glm::dvec3(0.0, 0.0, 1.0));
  }
  const ClosestPoint below = p->closest(kCenter + glm::dvec3(2.0, 0.5, -1.0));
  EXPECT_EQ(below.position, kCenter + glm::dvec3(kHalf, 0.5, 0.0));
  EXPECT_NEAR(below.distance, std::hypot(0.5, 1.0), 1e-15);
}

TEST(Plane, rayMeetsTheSquareOnlyInsideIt) {
  const auto p = plane();
  EXPECT_NEAR(
      *p->intersect(kCenter + glm::dvec3(0.3, 0.2, 2.0), glm::dvec3(0.1, 0.0, -0.5), 0.0, 10.0),
      4.0, 1e-14);
  EXPECT_FALSE(
      p->intersect(kCenter + glm::dvec3(1.4, 0.0, 1.0), glm::dvec3(0.2, 0.0, -1.0), 0.0, 10.0));
  EXPECT_FALSE(
      p->intersect(kCenter + glm::dvec3(0.0, 0.0, 1.0), glm::dvec3(1.0, 0.0, 0.0), 0.0, 10.0));
}

TEST(Sheets, areaAndBoundsCoverBothSheets) {
  const auto s = sheets();
  EXPECT_EQ(s->name(), "sheets");
  EXPECT_DOUBLE_EQ(s->area(), 8.0 * kHalf * kHalf);
  EXPECT_FALSE(s->isClosed());
  EXPECT_EQ(s->boundsMin(), kCenter + glm::dvec3(-kHalf, -kHalf, -kGap / 2));
  EXPECT_EQ(s->boundsMax(), kCenter + glm::dvec3(kHalf, kHalf, kGap / 2));
}

TEST(Sheets, samplesSplitEvenlyWithOpposedNormals) {
  const auto s = sheets();
  test::expectSamplesOnSurface(*s, sheetsDistance, 10000, 1e-15);
  std::mt19937_64 rng(2);
  constexpr int kSamples = 100000;
  int upper = 0;
  for (int i = 0; i < kSamples; ++i) {
    const SurfacePoint p = s->sample(rng);
    const bool isUpper = p.position.z > kCenter.z;
    EXPECT_EQ(p.normal, glm::dvec3(0.0, 0.0, isUpper ? 1.0 : -1.0));
    upper += isUpper;
  }
  EXPECT_NEAR(double(upper) / kSamples, 0.5, 4.0 * std::sqrt(0.25 / kSamples));
}

TEST(Sheets, closestPointPicksTheNearerSheetAndItsNormal) {
  const auto s = sheets();
  const std::vector<glm::dvec3> surface = test::samplePositions(*s, 20000, 3);
  std::mt19937_64 rng(7);
  for (int i = 0; i < 100; ++i) {
    const glm::dvec3 q = test::randomPoint(rng, kCenter - 2.0, kCenter + 2.0);
    test::expectClosestIsExact(*s, sheetsDistance, q, surface, false);
  }
  const ClosestPoint up = s->closest(kCenter + glm::dvec3(0.1, 0.2, 0.004));
  EXPECT_EQ(up.normal, glm::dvec3(0.0, 0.0, 1.0));
  EXPECT_NEAR(up.distance, kGap / 2 - 0.004, 1e-15);
  const ClosestPoint down = s->closest(kCenter + glm::dvec3(0.1, 0.2, -0.004));
  EXPECT_EQ(down.normal, glm::dvec3(0.0, 0.0, -1.0));
  EXPECT_NEAR(down.position.z, kCenter.z - kGap / 2, 1e-15);
}

TEST(Sheets, verticalRayCrossesTheUpperSheetThenTheLower) {
  const auto s = sheets();
  const glm::dvec3 o = kCenter + glm::dvec3(0.5, -0.5, 1.0);
  const glm::dvec3 d(0.0, 0.0, -1.0);
  const double first = *s->intersect(o, d, 0.0, 10.0);
  EXPECT_NEAR(first, 1.0 - kGap / 2, 1e-14);
  EXPECT_NEAR(*s->intersect(o, d, first, 10.0), 1.0 + kGap / 2, 1e-14);
  EXPECT_FALSE(s->intersect(o, d, 1.0 + kGap / 2, 10.0));
  EXPECT_FALSE(s->intersect(o, -d, 0.0, 10.0));
}

}  // namespace
}  // namespace iso
