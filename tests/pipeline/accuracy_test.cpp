// The accuracy targets of the default conversion, measured against the analytic truth both ways
// (specs/pipeline.md; iso eval's metric): 200k-point scans of a sphere and a torus.
#include <gtest/gtest.h>

#include "pipeline_support.h"

namespace iso {
namespace {

struct Case {
  std::string shape;
  bool normals;
  double noise;
};

nlohmann::json measure(const Case& c, uint64_t rays = 20000) {
  test::TempDir dir;
  const test::Converted converted =
      test::convertAndLoad(test::scanOf(c.shape, 200000, c.normals, c.noise), dir / "scan.iso");
  ShapeParams params;
  params.name = c.shape;
  const nlohmann::json e = test::evaluate(converted, *makeShape(params), rays);
  std::printf(
      "%s normals=%d noise=%.2f: rms %.4f max %.4f spacings, normals median %.3f p99 %.3f deg, "
      "outward %.5f, "
      "holes %llu/%llu, %.2f bytes/leaf\n",
      c.shape.c_str(), int(c.normals), c.noise, e["rms_over_spacing"].get<double>(),
      e["max_over_spacing"].get<double>(), e["normal_median_deg"].get<double>(),
      e["normal_p99_deg"].get<double>(), e["normal_outward_fraction"].get<double>(),
      (unsigned long long)e["holes"].get<uint64_t>(),
      (unsigned long long)e["rays_hitting_truth"].get<uint64_t>(),
      converted.report["file"]["bytes_per_leaf"].get<double>());
  return e;
}

void expectCleanTargets(const nlohmann::json& e) {
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.10);
  EXPECT_LE(e["max_over_spacing"].get<double>(), 0.5);
  EXPECT_LE(e["normal_median_deg"].get<double>(), 1.0);
  EXPECT_LE(e["normal_p99_deg"].get<double>(), 5.0);
  EXPECT_EQ(e["holes"].get<uint64_t>(), 0u);
  EXPECT_GT(e["rays_hitting_truth"].get<uint64_t>(), 1000u);
}

TEST(Accuracy, cleanSphereWithNormalsMeetsTheTargets) {
  expectCleanTargets(measure({"sphere", true, 0.0}));
}

TEST(Accuracy, cleanTorusWithNormalsMeetsTheTargets) {
  expectCleanTargets(measure({"torus", true, 0.0}));
}

TEST(Accuracy, sphereWithoutNormalsIsAccurateAndOrientedOutward) {
  const nlohmann::json e = measure({"sphere", false, 0.0});
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.15);
  EXPECT_GE(e["normal_outward_fraction"].get<double>(), 0.999);
}

TEST(Accuracy, torusWithoutNormalsIsAccurateAndOrientedOutward) {
  const nlohmann::json e = measure({"torus", false, 0.0});
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.15);
  EXPECT_GE(e["normal_outward_fraction"].get<double>(), 0.999);
}

TEST(Accuracy, noisySphereMeetsTheTarget) {
  const nlohmann::json e = measure({"sphere", true, 0.5});
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.35);
}

TEST(Accuracy, hundredThousandRaysAtAClosedShapeNeverLeak) {
  const nlohmann::json e = measure({"torus", true, 0.0}, 100000);
  EXPECT_GE(e["rays_hitting_truth"].get<uint64_t>(), 50000u);
  EXPECT_EQ(e["holes"].get<uint64_t>(), 0u);
}

}  // namespace
}  // namespace iso

namespace iso {
namespace {

// The paper's layout takes 56 bytes per leaf (8 corners of a distance, a normal and a color).
// With colors, at the error of the sphere test above, the file must be smaller per leaf.
TEST(Size, bytesPerLeafBeatThePapersLayoutWithColors) {
  PointCloud points = test::scanOf("sphere", 200000);
  points.colors.resize(points.size());
  for (size_t i = 0; i < points.size(); ++i)
    points.colors[i] = glm::vec3(0.5f + 0.5f * float(points.positions[i].x), 0.3f,
                                 0.5f - 0.4f * float(points.positions[i].z));
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(points, dir / "colored.iso");
  ShapeParams params;
  const nlohmann::json e = test::evaluate(c, *makeShape(params));
  const double bytesPerLeaf = c.report["file"]["bytes_per_leaf"].get<double>();
  std::printf("with colors: %.2f bytes/leaf, %.3f bytes/point, rms %.4f spacings\n", bytesPerLeaf,
              c.report["file"]["bytes_per_point"].get<double>(),
              e["rms_over_spacing"].get<double>());
  EXPECT_TRUE(c.surface.hasColors());
  EXPECT_LE(e["rms_over_spacing"].get<double>(), 0.10);
  EXPECT_LT(bytesPerLeaf, 56.0);
}

}  // namespace
}  // namespace iso
