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
  std::printf("%s normals=%d noise=%.2f: rms %.4f max %.4f spacings, normals median %.3f p99 %.3f deg, outward %.5f, "
              "holes %llu/%llu, %.2f bytes/leaf\n",
              c.shape.c_str(), int(c.normals), c.noise, e["rms_over_spacing"].get<double>(),
              e["max_over_spacing"].get<double>(), e["normal_median_deg"].get<double>(),
              e["normal_p99_deg"].get<double>(), e["normal_outward_fraction"].get<double>(),
              (unsigned long long)e["holes"].get<uint64_t>(), (unsigned long long)e["rays_hitting_truth"].get<uint64_t>(),
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

TEST(Accuracy, cleanSphereWithNormalsMeetsTheTargets) { expectCleanTargets(measure({"sphere", true, 0.0})); }

TEST(Accuracy, cleanTorusWithNormalsMeetsTheTargets) { expectCleanTargets(measure({"torus", true, 0.0})); }

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
