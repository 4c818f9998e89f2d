// generateScan(): counts, noise, density ramp, offset, determinism, and the spacing formula.
#include <tbb/global_control.h>

#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>

#include "pipeline/geom/generate.h"
#include "pipeline/geom/shape.h"
#include "tests/geom/meshes.h"

namespace iso {
namespace {

TEST(ExpectedSpacing, isHalfTheInverseSquareRootOfDensity) {
  EXPECT_DOUBLE_EQ(expectedSpacing(4.0, 100), 0.1);
  EXPECT_DOUBLE_EQ(expectedSpacing(1.0, 1), 0.5);
}

TEST(GenerateScan, makesExactlyCountPointsOnTheSurfaceWithUnitNormals) {
  const auto shape = makeShape({.name = "torus"});
  const PointCloud cloud = generateScan(*shape, {.count = 100003});  // not a whole block
  ASSERT_EQ(cloud.size(), 100003u);
  ASSERT_EQ(cloud.normals.size(), 100003u);
  EXPECT_FALSE(cloud.hasColors());
  for (size_t i = 0; i < cloud.size(); ++i) {
    const ClosestPoint c = shape->closest(cloud.positions[i]);
    ASSERT_LE(c.distance, 1e-14);
    ASSERT_NEAR(glm::length(cloud.normals[i]), 1.0f, 1e-6f);
    ASSERT_GT(glm::dot(glm::dvec3(cloud.normals[i]), c.normal), 1.0 - 1e-6);
  }
}

TEST(GenerateScan, leavesNormalsOutWhenAsked) {
  const auto shape = makeShape({});
  const PointCloud cloud = generateScan(*shape, {.count = 10, .normals = false});
  EXPECT_EQ(cloud.size(), 10u);
  EXPECT_FALSE(cloud.hasNormals());
}

TEST(GenerateScan, noiseHasTheRequestedStandardDeviationAlongTheNormal) {
  const auto shape = makeShape({.radius = 2.0});
  constexpr uint64_t kCount = 200000;
  const double sigma = 0.5 * expectedSpacing(shape->area(), kCount);
  const PointCloud cloud = generateScan(*shape, {.count = kCount, .noise = 0.5, .seed = 9});
  double sum = 0.0, sum2 = 0.0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const double offset = glm::length(cloud.positions[i]) - 2.0;
    sum += offset;
    sum2 += offset * offset;
    // The displacement is along the true (radial) normal.
    ASSERT_GT(glm::dot(glm::normalize(cloud.positions[i]), glm::dvec3(cloud.normals[i])),
              1.0 - 1e-6);
  }
  const double mean = sum / kCount;
  EXPECT_NEAR(mean, 0.0, 5.0 * sigma / std::sqrt(double(kCount)));
  EXPECT_NEAR(std::sqrt(sum2 / kCount - mean * mean), sigma, 0.02 * sigma);
}

// On the plane x is uniform before thinning, so the density along x is ratio^u exactly: the counts
// in the first and last tenth of the square differ by the ratio of ∫ratio^u over each.
TEST(GenerateScan, densityRatioScalesTheDensityAcrossX) {
  const auto shape = makeShape({.name = "plane"});
  constexpr double kRatio = 8.0;
  const PointCloud cloud = generateScan(*shape, {.count = 400000, .densityRatio = kRatio});
  double sparse = 0.0, dense = 0.0;
  for (const glm::dvec3& p : cloud.positions) {
    const double u = (p.x + 1.0) / 2.0;
    sparse += u < 0.1;
    dense += u > 0.9;
  }
  const auto integral = [&](double u0, double u1) {
    return (std::pow(kRatio, u1) - std::pow(kRatio, u0)) / std::log(kRatio);
  };
  const double expected = integral(0.9, 1.0) / integral(0.0, 0.1);
  EXPECT_NEAR(dense / sparse, expected, 0.04 * expected);
  EXPECT_NEAR(dense / cloud.size(), integral(0.9, 1.0) / integral(0.0, 1.0), 0.01);
}

TEST(GenerateScan, offsetMovesEveryPoint) {
  const auto shape = makeShape({.name = "cube"});
  const glm::dvec3 offset(500000.0, 4900000.0, 0.0);
  const PointCloud plain = generateScan(*shape, {.count = 1000, .noise = 1.0});
  const PointCloud moved = generateScan(*shape, {.count = 1000, .noise = 1.0, .offset = offset});
  for (size_t i = 0; i < plain.size(); ++i) {
    ASSERT_EQ(moved.positions[i], plain.positions[i] + offset);
    ASSERT_EQ(moved.normals[i], plain.normals[i]);
  }
}

PointCloud scanWithThreads(const Shape& shape, int threads, uint64_t seed) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  return generateScan(shape, {.count = 300000, .noise = 0.3, .densityRatio = 3.0, .seed = seed});
}

TEST(GenerateScan, isDeterministicAcrossRunsAndThreadCounts) {
  const auto shape = makeShape({.name = "torus"});
  const PointCloud reference = scanWithThreads(*shape, 1, 42);
  for (int threads : {1, 2, 3, 8}) {
    const PointCloud again = scanWithThreads(*shape, threads, 42);
    ASSERT_EQ(again.positions, reference.positions) << threads << " threads";
    ASSERT_EQ(again.normals, reference.normals) << threads << " threads";
  }
  EXPECT_NE(scanWithThreads(*shape, 2, 43).positions, reference.positions);
}

// Scans are part of experiments' definitions: the same seed must give the same points on every
// machine and in every version. These values pin the random number derivation (mt19937_64 bits,
// per-block seeds, Box–Muller, rejection order); the tolerance only allows last-bit differences of
// the math library's sin, cos and log.
TEST(GenerateScan, pointsOfASeedArePinned) {
  const PointCloud sphere = generateScan(*makeShape({}), {.count = 1, .seed = 1});
  EXPECT_NEAR(sphere.positions[0].x, -0.46968347639916325, 1e-12);
  EXPECT_NEAR(sphere.positions[0].y, 0.87504544759754221, 1e-12);
  EXPECT_NEAR(sphere.positions[0].z, 0.11701665110749704, 1e-12);
  const PointCloud torus =
      generateScan(*makeShape({.name = "torus"}),
                   {.count = 70000, .noise = 0.5, .densityRatio = 4.0, .seed = 7});
  const glm::dvec3 last = torus.positions.back();  // in the second block
  EXPECT_NEAR(last.x, -0.46459409038238697, 1e-12);
  EXPECT_NEAR(last.y, 1.2640547896659831, 1e-12);
  EXPECT_NEAR(last.z, 0.037134514079520127, 1e-12);
}

// Brute-force nearest neighbours of a small scan: their mean is the expected spacing.
TEST(GenerateScan, meanNearestNeighbourDistanceMatchesExpectedSpacing) {
  const auto shape = makeShape({.radius = 3.0});
  constexpr uint64_t kCount = 5000;
  const PointCloud cloud = generateScan(*shape, {.count = kCount, .seed = 5});
  double sum = 0.0;
  for (size_t i = 0; i < kCount; ++i) {
    double nearest = std::numeric_limits<double>::infinity();
    for (size_t j = 0; j < kCount; ++j)
      if (j != i) nearest = std::min(nearest, glm::length(cloud.positions[i] - cloud.positions[j]));
    sum += nearest;
  }
  const double spacing = expectedSpacing(shape->area(), kCount);
  EXPECT_NEAR(sum / kCount, spacing, 0.03 * spacing);
}

TEST(GenerateScan, samplesMeshShapes) {
  const auto mesh = makeMeshShape(test::icosphere(3));
  const PointCloud cloud = generateScan(*mesh, {.count = 5000, .seed = 2});
  for (const glm::dvec3& p : cloud.positions) ASSERT_LE(mesh->closest(p).distance, 1e-15);
}

TEST(GenerateScan, rejectsBadOptions) {
  const auto shape = makeShape({});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(generateScan(*shape, {.count = 0}), std::invalid_argument);
  EXPECT_THROW(generateScan(*shape, {.noise = -0.1}), std::invalid_argument);
  EXPECT_THROW(generateScan(*shape, {.noise = nan}), std::invalid_argument);
  EXPECT_THROW(generateScan(*shape, {.densityRatio = 0.5}), std::invalid_argument);
  EXPECT_THROW(generateScan(*shape, {.densityRatio = std::numeric_limits<double>::infinity()}),
               std::invalid_argument);
  EXPECT_THROW(generateScan(*shape, {.offset = {0.0, nan, 0.0}}), std::invalid_argument);
}

}  // namespace
}  // namespace iso
