// Color error of `iso eval --points`: the PSNR of 8-bit sRGB colors where the points project onto
// the surface, against values known exactly.
#include <gtest/gtest.h>

#include <cmath>

#include "iso/quantize.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

glm::vec3 colorOf(uint8_t r, uint8_t g, uint8_t b) {
  return {srgb8ToLinear(r), srgb8ToLinear(g), srgb8ToLinear(b)};
}

TEST(ColorError, psnrOfAUniformColorAgainstAnotherIsExact) {
  // A sphere all of sRGB (200, 100, 50): every corner stores exactly that color, so wherever a
  // point projects the file's color is (200, 100, 50).
  PointCloud points = test::scanOf("sphere", 20000);
  points.colors.assign(points.size(), colorOf(200, 100, 50));
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(points, dir / "uniform.iso");
  ASSERT_TRUE(c.surface.hasColors());
  // The same colors: no error but float rounding.
  nlohmann::json same = evaluateAgainstPoints(c.surface, points);
  EXPECT_NEAR(same["color"]["rmse_8bit"].get<double>(), 0.0, 1e-3);
  EXPECT_GT(same["color_psnr_db"].get<double>(), 100.0) << same.dump();
  EXPECT_GE(same["color"]["points"].get<uint64_t>(), points.size() * 99 / 100);
  // Red 10 levels off in every point: MSE = 10² / 3 over the channels.
  points.colors.assign(points.size(), colorOf(210, 100, 50));
  const nlohmann::json off = evaluateAgainstPoints(c.surface, points);
  const double expected = 10.0 * std::log10(255.0 * 255.0 / (100.0 / 3.0));
  EXPECT_NEAR(off["color_psnr_db"].get<double>(), expected, 0.01) << off.dump();
  // Without colors in the points there is nothing to compare.
  points.colors.clear();
  EXPECT_TRUE(evaluateAgainstPoints(c.surface, points)["color"].is_null());
}

TEST(ColorError, aSmoothColorFieldSurvivesAndSwappedChannelsDoNot) {
  PointCloud points = test::scanOf("sphere", 50000);
  points.colors.resize(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::dvec3& p = points.positions[i];
    points.colors[i] = glm::vec3(0.5 + 0.4 * p.x, 0.3 + 0.2 * p.y, 0.6 - 0.4 * p.z);
  }
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(points, dir / "smooth.iso");
  const double good = evaluateAgainstPoints(c.surface, points)["color_psnr_db"].get<double>();
  for (glm::vec3& color : points.colors) std::swap(color.r, color.b);
  const double swapped = evaluateAgainstPoints(c.surface, points)["color_psnr_db"].get<double>();
  std::printf("smooth colors: %.2f dB; red and blue swapped: %.2f dB\n", good, swapped);
  EXPECT_GT(good, 40.0);
  EXPECT_LT(swapped, 25.0);
}

}  // namespace
}  // namespace iso
