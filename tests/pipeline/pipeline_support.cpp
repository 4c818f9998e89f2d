#include "pipeline/base/options.h"
#include "tests/pipeline/pipeline_support.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

namespace iso::test {

PointCloud scanOf(const std::string& shape, uint64_t count, bool normals, double noise,
                  uint64_t seed) {
  ShapeParams params;
  params.name = shape;
  return scanOf(params, count, normals, noise, seed);
}

ShapeParams turnedShape(const std::string& name) {
  ShapeParams params;
  params.name = name;
  params.rotation = {25.0, 15.0, 0.0};
  return params;
}

PointCloud scanOf(const ShapeParams& params, uint64_t count, bool normals, double noise,
                  uint64_t seed) {
  const std::unique_ptr<Shape> truth = makeShape(params);
  GenerateOptions options;
  options.count = count;
  options.normals = normals;
  options.noise = noise;
  options.seed = seed;
  return generateScan(*truth, options);
}

Converted convertAndLoad(const PointCloud& points, const std::filesystem::path& path,
                         const BuildOptions& options) {
  nlohmann::json report = convertToIso(points, path, options);
  return {std::move(report), SurfaceModel::load(Reader::open(path))};
}

nlohmann::json evaluate(const Converted& converted, const Shape& truth, uint64_t rays) {
  EvalOptions options;
  options.rays = rays;
  options.truthSamples = 50000;
  return evaluateAgainstShape(converted.surface, truth,
                              converted.report["spacing"].get<double>(), options);
}

void writePpm(const std::filesystem::path& path, uint32_t width, uint32_t height,
              const std::vector<uint8_t>& rgb) {
  const std::string header =
      "P6\n" + std::to_string(width) + " " + std::to_string(height) + "\n255\n";
  std::vector<std::byte> bytes(header.size() + rgb.size());
  std::memcpy(bytes.data(), header.data(), header.size());
  std::memcpy(bytes.data() + header.size(), rgb.data(), rgb.size());
  writeFile(path, bytes);
}

std::vector<uint8_t> randomImage(uint32_t width, uint32_t height, uint32_t seed) {
  std::mt19937 random(seed);
  std::vector<uint8_t> rgb(size_t(width) * height * 3);
  for (uint8_t& b : rgb) b = uint8_t(random() & 0xFF);
  return rgb;
}

void expectSameClosure(const Closure& a, const Closure& b, const std::string& what) {
  EXPECT_EQ(a.cornersInUse, b.cornersInUse) << what;
  const CornerField &x = a.corners, &y = b.corners;
  ASSERT_EQ(x.size(), y.size()) << what;
  size_t levels = 0, values = 0;
  for (uint32_t e = 0; e < x.size(); ++e) {
    levels += x.coarsestLevel[e] != y.coarsestLevel[e];
    values += std::memcmp(&x.value[e], &y.value[e], sizeof(CornerSample)) != 0;
  }
  EXPECT_EQ(levels, 0u) << what << ": corner levels that differ";
  EXPECT_EQ(values, 0u) << what << ": corner values that differ";
  ASSERT_EQ(a.hanging.size(), b.hanging.size()) << what;
  for (size_t i = 0; i < a.hanging.size(); ++i) {
    const HangingCorner &h = a.hanging[i], &k = b.hanging[i];
    ASSERT_TRUE(h.corner == k.corner && h.sourceCount == k.sourceCount && h.sources == k.sources)
        << what << ": hanging corner " << i;
  }
}

}  // namespace iso::test
