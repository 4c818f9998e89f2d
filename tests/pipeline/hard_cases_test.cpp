// The hard cases of specs/pipeline.md §11: each has an asserted outcome, a clear error or a valid
// file with bounded error; none may produce NaN, crash or hang.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <glm/geometric.hpp>

#include "iso/verify.h"
#include "pipeline_support.h"

namespace iso {
namespace {

std::string conversionError(const PointCloud& points) {
  test::TempDir dir;
  try {
    convertToIso(points, dir / "out.iso", BuildOptions{});
  } catch (const ConvertError& error) {
    EXPECT_FALSE(std::filesystem::exists(dir / "out.iso"));
    return error.what();
  }
  ADD_FAILURE() << "converted";
  return {};
}

std::unique_ptr<Shape> shape(const std::string& name) {
  ShapeParams params;
  params.name = name;
  return makeShape(params);
}

// Convert, verify the file, and measure it against the named truth.
nlohmann::json convertAndMeasure(const PointCloud& points, const Shape& truth, nlohmann::json* report = nullptr,
                                 BuildOptions options = {}) {
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(points, dir / "out.iso", options);
  EXPECT_TRUE(verifyFile(Reader::open(dir / "out.iso")).ok());
  if (report) *report = c.report;
  const nlohmann::json e = test::evaluate(c, truth);
  EXPECT_TRUE(std::isfinite(e["rms"].get<double>()));
  std::printf("%s: rms %.4f max %.4f spacings, holes %llu\n", truth.name().c_str(), e["rms_over_spacing"].get<double>(),
              e["max_over_spacing"].get<double>(), (unsigned long long)e["holes"].get<uint64_t>());
  return e;
}

TEST(HardCases, emptyInputIsAClearError) {
  EXPECT_NE(conversionError({}).find("no points"), std::string::npos);
}

TEST(HardCases, oneOrTwoPointsAreAClearError) {
  PointCloud one, two;
  one.positions = {{1, 2, 3}};
  two.positions = {{1, 2, 3}, {1, 2, 4}};
  EXPECT_NE(conversionError(one).find("at least 3 distinct points"), std::string::npos);
  EXPECT_NE(conversionError(two).find("at least 3 distinct points"), std::string::npos);
}

TEST(HardCases, identicalPointsAreAClearError) {
  PointCloud same;
  same.positions.assign(1000, glm::dvec3(5.0, -1.0, 2.0));
  EXPECT_NE(conversionError(same).find("the input has 1"), std::string::npos);
}

TEST(HardCases, collinearPointsAreAClearError) {
  PointCloud line;
  for (int i = 0; i < 1000; ++i) line.positions.push_back(glm::dvec3(1.0, 2.0, 3.0) + double(i) * glm::dvec3(0.3, -0.2, 0.1));
  EXPECT_NE(conversionError(line).find("one line"), std::string::npos);
}

TEST(HardCases, halfExactDuplicatesGiveTheSameSurface) {
  const PointCloud base = test::scanOf("sphere", 40000);
  PointCloud doubled = base;
  for (size_t i = 0; i < base.size(); i += 2) {  // every other point twice more: 50 % duplicates
    doubled.positions.push_back(base.positions[i]);
    doubled.normals.push_back(base.normals[i]);
  }
  nlohmann::json report;
  const nlohmann::json a = convertAndMeasure(base, *shape("sphere"));
  const nlohmann::json b = convertAndMeasure(doubled, *shape("sphere"), &report);
  EXPECT_EQ(report["points"]["duplicates_merged"].get<uint64_t>(), base.size() / 2);
  EXPECT_NEAR(b["rms"].get<double>(), a["rms"].get<double>(), 0.05 * a["rms"].get<double>());
}

TEST(HardCases, coplanarPointsGiveAPlane) {
  const nlohmann::json e = convertAndMeasure(test::scanOf("plane", 40000), *shape("plane"));
  EXPECT_LE(e["truth_to_iso"]["rms_over_spacing"].get<double>(), 0.10);
  EXPECT_EQ(e["holes"].get<uint64_t>(), 0u);
}

TEST(HardCases, earthCentredOffsetsKeepMillimetreDetail) {
  // A sphere of 10 cm radius, 6,400 km from the origin, sampled every 0.8 mm.
  ShapeParams params;
  params.radius = 0.1;
  params.center = glm::dvec3(6.4e6, 1.2e5, -3.0e4);
  const std::unique_ptr<Shape> truth = makeShape(params);
  GenerateOptions g;
  g.count = 60000;
  const PointCloud points = generateScan(*truth, g);
  nlohmann::json report;
  const nlohmann::json e = convertAndMeasure(points, *truth, &report);
  EXPECT_LT(report["mean_spacing"].get<double>(), 1e-3);
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.10);
  EXPECT_LT(e["max"].get<double>(), 0.5e-3);  // below half a millimetre everywhere
}

TEST(HardCases, tenThousandFoldDensityVariationGivesAValidSurface) {
  ShapeParams params;
  const std::unique_ptr<Shape> truth = makeShape(params);
  GenerateOptions g;
  g.count = 100000;
  g.densityRatio = 1e4;
  const nlohmann::json e = convertAndMeasure(generateScan(*truth, g), *truth);
  EXPECT_LE(e["hole_rate"].get<double>(), 0.001);
  EXPECT_LE(e["rms_over_diagonal"].get<double>(), 2e-3);
}

TEST(HardCases, sheetsCloserThanTheRadiusStaySeparate) {
  ShapeParams params;
  params.name = "sheets";
  params.gap = 0.01;  // 2 spacings; the radius of influence is about 3.6 spacings
  const std::unique_ptr<Shape> truth = makeShape(params);
  GenerateOptions g;
  g.count = 100000;
  nlohmann::json report;
  const nlohmann::json e = convertAndMeasure(generateScan(*truth, g), *truth, &report);
  EXPECT_LT(params.gap, report["median_radius"].get<double>());
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.25);
  EXPECT_LE(e["hole_rate"].get<double>(), 0.001);
}

TEST(HardCases, sharpCubeEdgesHaveBoundedError) {
  const nlohmann::json e = convertAndMeasure(test::scanOf("cube", 100000), *shape("cube"));
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.5);
  EXPECT_LE(e["max_over_spacing"].get<double>(), 5.0);
  EXPECT_EQ(e["holes"].get<uint64_t>(), 0u);
}

TEST(HardCases, openSurfaceOverhangsItsBoundaryByLittle) {
  nlohmann::json report;
  const nlohmann::json e = convertAndMeasure(test::scanOf("plane", 40000), *shape("plane"), &report);
  // The surface may reach past the boundary by about a radius of influence, not more.
  EXPECT_LE(e["iso_to_truth"]["max"].get<double>(), 2.0 * report["median_radius"].get<double>());
}

PointCloud withSpoiledNormals(uint64_t every, const glm::vec3& replacement, bool flip) {
  PointCloud points = test::scanOf("sphere", 100000);
  for (size_t i = 0; i < points.size(); i += every) points.normals[i] = flip ? -points.normals[i] : replacement;
  return points;
}

TEST(HardCases, zeroAndNanNormalsAreEstimated) {
  for (const glm::vec3& bad : {glm::vec3(0.0f), glm::vec3(std::nanf(""), 0.0f, 1.0f)}) {
    nlohmann::json report;
    const nlohmann::json e = convertAndMeasure(withSpoiledNormals(10, bad, false), *shape("sphere"), &report);
    EXPECT_EQ(report["normals"]["estimated"].get<uint64_t>(), 10000u);
    EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.15);
    EXPECT_GE(e["normal_outward_fraction"].get<double>(), 0.999);
  }
}

TEST(HardCases, flippedInputNormalsAreRepaired) {
  nlohmann::json report;
  const nlohmann::json e = convertAndMeasure(withSpoiledNormals(20, {}, true), *shape("sphere"), &report);
  EXPECT_GE(report["normals"]["flipped_to_agree"].get<uint64_t>(), 4900u);  // of 5,000
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.15);
  EXPECT_EQ(e["holes"].get<uint64_t>(), 0u);
}

TEST(HardCases, farOutliersAreRemovedAndCounted) {
  PointCloud points = test::scanOf("sphere", 40000);
  for (int i = 0; i < 5; ++i) {
    points.positions.push_back(glm::dvec3(1000.0 + 37.0 * i, -500.0 * i, 2000.0));
    points.normals.push_back(glm::vec3(0, 0, 1));
  }
  nlohmann::json report;
  const nlohmann::json e = convertAndMeasure(points, *shape("sphere"), &report);
  EXPECT_EQ(report["points"]["outliers_removed"].get<uint64_t>(), 5u);
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.15);
}

TEST(HardCases, maximumDepthWithManyPointsPerCellTerminates) {
  BuildOptions options;
  options.maxDepth = 3;  // leaves of 1/8 of the frame with thousands of points each
  nlohmann::json report;
  const nlohmann::json e = convertAndMeasure(test::scanOf("sphere", 50000), *shape("sphere"), &report, options);
  EXPECT_LE(report["octree"]["max_level"].get<int>(), 3);
  EXPECT_EQ(e["holes"].get<uint64_t>(), 0u);
  EXPECT_LE(e["rms_over_diagonal"].get<double>(), 0.02);  // coarse, but a sphere
}

TEST(HardCases, thousandToOneAspectRatioConverts) {
  // A ribbon 1000 long and 1 wide, sampled uniformly: the frame is 1000 wide, the leaves small.
  PointCloud ribbon;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> along(-500.0, 500.0), across(-0.5, 0.5);
  for (int i = 0; i < 100000; ++i) {
    ribbon.positions.push_back({along(rng), across(rng), 0.0});
    ribbon.normals.push_back({0.0f, 0.0f, 1.0f});
  }
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(ribbon, dir / "ribbon.iso");
  EXPECT_TRUE(verifyFile(Reader::open(dir / "ribbon.iso")).ok());
  const auto& a = c.report["accuracy"];
  EXPECT_LE(a["unprojected"].get<uint64_t>() * 100, a["samples"].get<uint64_t>());
  EXPECT_LE(a["rms_over_spacing"].get<double>(), 0.1);
}

}  // namespace
}  // namespace iso
