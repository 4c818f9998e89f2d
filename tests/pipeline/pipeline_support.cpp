#include "pipeline_support.h"

namespace iso::test {

PointCloud scanOf(const std::string& shape, uint64_t count, bool normals, double noise,
                  uint64_t seed) {
  ShapeParams params;
  params.name = shape;
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
                              converted.report["mean_spacing"].get<double>(), options);
}

}  // namespace iso::test
