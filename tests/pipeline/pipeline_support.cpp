#include "pipeline/base/options.h"
#include "tests/pipeline/pipeline_support.h"

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

}  // namespace iso::test
