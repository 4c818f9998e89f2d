// `iso eval`'s comparisons: every level-of-detail cut against the points, and two files against
// each other, with answers known exactly.
#include <gtest/gtest.h>

#include <cmath>

#include "iso/quantize.h"
#include "pipeline/base/options.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

TEST(EvalLevels, cutsGetCloserLevelByLevelAndTheLastIsTheWholeSurface) {
  test::TempDir dir;
  const PointCloud points = test::scanOf("sphere", 40000);
  BuildOptions options;
  options.chunkNodes = 400;  // cuts across chunks
  const test::Converted c = test::convertAndLoad(points, dir / "s.iso", options);
  const nlohmann::json levels = evaluateLevels(Reader::open(dir / "s.iso"), points);
  ASSERT_GE(levels.size(), 4u);
  const nlohmann::json whole = evaluateAgainstPoints(c.surface, points);
  // The deepest cut is every leaf: the same surface, the same numbers.
  EXPECT_EQ(levels.back()["patches"].get<size_t>(), c.surface.leaves().size());
  EXPECT_DOUBLE_EQ(levels.back()["rms"].get<double>(), whole["rms"].get<double>());
  for (size_t i = 1; i < levels.size(); ++i) {
    EXPECT_GT(levels[i]["patches"].get<size_t>(), levels[i - 1]["patches"].get<size_t>());
    std::printf("level %d: %zu patches, RMS %.3f spacings\n", levels[i]["level"].get<int>(),
                levels[i]["patches"].get<size_t>(), levels[i]["rms_over_spacing"].get<double>());
  }
  // Coarse cuts are far worse than the leaves (level 0, one patch, has no zero set at all: every
  // point unprojected), and every cut is better than the one above it from level 3 on.
  EXPECT_EQ(levels[0]["unprojected"].get<size_t>(), points.size());
  EXPECT_GT(levels[1]["rms"].get<double>(), 10 * whole["rms"].get<double>());
  for (size_t i = 1; i < levels.size(); ++i) {
    if (levels[i]["level"].get<int>() < 3) continue;
    EXPECT_LE(levels[i]["rms"].get<double>(), levels[i - 1]["rms"].get<double>() * 1.0001);
  }
}

TEST(EvalAgainstFile, concentricSpheresAreTheirGapApartAndColorsTheirDifference) {
  test::TempDir dir;
  const auto sphere = [&](double radius, uint8_t red, const char* name) {
    ShapeParams params;
    params.radius = radius;
    GenerateOptions generate;
    generate.count = 40000;
    PointCloud points = generateScan(*makeShape(params), generate);
    points.colors.assign(points.size(),
                         glm::vec3(srgb8ToLinear(red), srgb8ToLinear(100), srgb8ToLinear(50)));
    return test::convertAndLoad(points, dir / name);
  };
  const test::Converted a = sphere(1.0, 200, "a.iso"), b = sphere(1.05, 210, "b.iso");
  const nlohmann::json same = evaluateAgainstFile(a.surface, a.surface);
  EXPECT_LT(same["rms"].get<double>(), 1e-6);
  EXPECT_TRUE(same["color_psnr_db"].is_null());  // equal colors everywhere
  const nlohmann::json e = evaluateAgainstFile(a.surface, b.surface);
  std::printf("spheres 1 and 1.05: RMS %.5f (a→b %.5f, b→a %.5f), color %.3f dB\n",
              e["rms"].get<double>(), e["a_to_b"]["rms"].get<double>(),
              e["b_to_a"]["rms"].get<double>(), e["color_psnr_db"].get<double>());
  const double spacing = a.report["spacing"].get<double>();
  EXPECT_NEAR(e["a_to_b"]["rms"].get<double>(), 0.05, 0.1 * spacing);
  EXPECT_NEAR(e["b_to_a"]["rms"].get<double>(), 0.05, 0.1 * spacing);
  // Red 10 levels apart in every sample: MSE = 10² / 3 over the channels.
  EXPECT_NEAR(e["color_psnr_db"].get<double>(), 10.0 * std::log10(255.0 * 255.0 / (100.0 / 3.0)),
              0.01);
}

}  // namespace
}  // namespace iso
