// iso-bench-appearance DATA_DIR OUT_DIR [--dragon SCAN]: what appearance costs and how well it is
// kept (specs/pipeline.md §16). In core, on the bundled scans:
//   1. the lion's scan colors: color PSNR against its own points at default settings and at
//      shallower depths;
//   2. a triplanar texture sampled at the points or at the corners: the color PSNR against the
//      texture at each input point (with its own normal), and the time the bake adds, for a
//      generated sphere and the parasaurolophus (both with true normals), with a coarse and a
//      fine random texture;
//   3. ambient occlusion: the time per million points and per million corners, at 16, 32 and 64
//   rays,
//      for the bunny and (with --dragon) a sampled dragon scan.
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <glm/common.hpp>
#include <random>
#include <string>
#include <vector>

#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/evaluate.h"
#include "pipeline/base/options.h"
#include "pipeline/convert/convert.h"
#include "pipeline/geom/generate.h"
#include "pipeline/geom/shape.h"
#include "pipeline/io/readers.h"
#include "pipeline/output/texture.h"

namespace {

using namespace iso;

double stageSeconds(const nlohmann::json& report, const std::string& name) {
  double s = 0.0;
  for (const auto& stage : report["stages"])
    if (stage["name"] == name) s += stage["seconds"].get<double>();
  return s;
}

// A random-color image as a binary PPM.
void writeRandomImage(const std::filesystem::path& path, uint32_t size, uint32_t seed) {
  std::mt19937 random(seed);
  const std::string header = fmt::format("P6\n{} {}\n255\n", size, size);
  std::string bytes = header;
  for (size_t i = 0; i < size_t(size) * size * 3; ++i) bytes.push_back(char(random() & 0xFF));
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size() || std::fclose(f) != 0)
    throw std::runtime_error("cannot write " + path.string());
}

struct Converted {
  nlohmann::json report;
  SurfaceModel surface;
};

Converted convert(const PointCloud& cloud, const std::filesystem::path& path,
                  const BuildOptions& options) {
  nlohmann::json report = convertToIso(cloud, path, options);
  return {std::move(report), SurfaceModel::load(Reader::open(path))};
}

double psnr(const SurfaceModel& surface, const PointCloud& truth) {
  const nlohmann::json e = evaluateAgainstPoints(surface, truth);
  return e["color_psnr_db"].is_null() ? 0.0 : e["color_psnr_db"].get<double>();
}

void lionColors(const std::filesystem::path& data, const std::filesystem::path& out) {
  const PointCloud lion = readPointFile(data / "lion_rgb.las");
  fmt::print("\n## 1. Scan colors: the lion ({} points, RGB), PSNR against its own colors\n\n",
             lion.size());
  fmt::print("| --max-depth | leaves | bytes/point | convert s | color PSNR dB |\n");
  fmt::print("|---:|---:|---:|---:|---:|\n");
  for (int depth : {20, 8, 7, 6}) {
    BuildOptions options;
    options.maxDepth = depth;
    const Converted c = convert(lion, out / "lion.iso", options);
    fmt::print("| {}{} | {} | {:.2f} | {:.2f} | {:.2f} |\n", depth, depth == 20 ? " (default)" : "",
               c.report["octree"]["leaves"].get<uint64_t>(),
               c.report["file"]["bytes_per_point"].get<double>(), c.report["seconds"].get<double>(),
               psnr(c.surface, lion));
  }
}

void textures(const std::filesystem::path& data, const std::filesystem::path& out) {
  fmt::print(
      "\n## 2. Triplanar textures: sampled at the points or at the corners\n\n"
      "Random-color images (every texel its own color), one repeat over the scan's largest "
      "extent, sharpness 4. Truth: the texture at each input point with its own normal.\n\n");
  fmt::print(
      "| scan | points | texture | at | color PSNR dB | convert s | without texture s | bake s "
      "| bake s per Mpt |\n");
  fmt::print("|---|---:|---|---|---:|---:|---:|---:|---:|\n");
  ShapeParams sphereParams;
  const auto sphere = makeShape(sphereParams);
  GenerateOptions generate;
  generate.count = 500000;
  const std::vector<std::pair<std::string, PointCloud>> scans = {
      {"sphere (generated)", generateScan(*sphere, generate)},
      {"parasaurolophus", readPointFile(data / "parasaurolophus_normals.ply")}};
  for (const auto& [name, cloud] : scans) {
    glm::dvec3 lo(1e300), hi(-1e300);
    for (const glm::dvec3& p : cloud.positions) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    const glm::dvec3 extent = hi - lo;
    const double scale = std::max({extent.x, extent.y, extent.z});
    const double plain = convert(cloud, out / "plain.iso", {}).report["seconds"].get<double>();
    for (uint32_t size : {32u, 256u}) {
      const auto image = out / fmt::format("random-{}.ppm", size);
      writeRandomImage(image, size, size);
      const TriplanarTexture texture(readLinearImage(image), scale, 4.0);
      PointCloud truth = cloud;
      truth.colors.resize(truth.size());
      for (size_t i = 0; i < truth.size(); ++i)
        truth.colors[i] = texture.color(truth.positions[i], glm::dvec3(truth.normals[i]));
      for (TextureAt at : {TextureAt::Points, TextureAt::Corners}) {
        BuildOptions options;
        options.texture = {image, scale, 4.0, at};
        const Converted c = convert(cloud, out / "textured.iso", options);
        const double seconds = c.report["seconds"].get<double>();
        const double bake = stageSeconds(c.report, "texture");  // its own stage either way
        fmt::print("| {} | {} | {}² | {} | {:.2f} | {:.2f} | {:.2f} | {:.3f} | {:.3f} |\n", name,
                   cloud.size(), size, at == TextureAt::Points ? "points" : "corners",
                   psnr(c.surface, truth), seconds, plain, bake,
                   bake / (double(cloud.size()) * 1e-6));
      }
    }
  }
}

void occlusion(const std::vector<std::pair<std::string, std::filesystem::path>>& scans,
               const std::filesystem::path& out) {
  fmt::print(
      "\n## 3. Ambient occlusion (radius: a tenth of the frame)\n\n"
      "| scan | points | leaves | corners | rays | occlusion s | s per Mpt | s per M corners "
      "| M rays/s | mean |\n");
  fmt::print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const auto& [name, path] : scans) {
    const PointCloud cloud = readPointFile(path);
    for (int rays : {16, 32, 64}) {
      BuildOptions options;
      options.occlusion = {true, rays, 0.0};
      const nlohmann::json r = convertToIso(cloud, out / "occluded.iso", options);
      const double s = stageSeconds(r, "occlusion");
      const double corners = r["occlusion"]["corners"].get<double>();
      fmt::print("| {} | {} | {} | {} | {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.3f} |\n", name,
                 cloud.size(), r["octree"]["leaves"].get<uint64_t>(), uint64_t(corners), rays, s,
                 s / (double(cloud.size()) * 1e-6), s / (corners * 1e-6), corners * rays / s * 1e-6,
                 r["occlusion"]["mean"].get<double>());
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    fmt::print(stderr, "usage: iso-bench-appearance DATA_DIR OUT_DIR [--dragon SCAN]\n");
    return 2;
  }
  const std::filesystem::path data = argv[1], out = argv[2];
  std::vector<std::pair<std::string, std::filesystem::path>> occluded = {
      {"bunny", data / "bunny_zipper.ply"}};
  for (int i = 3; i + 1 < argc; i += 2)
    if (std::strcmp(argv[i], "--dragon") == 0)
      occluded.push_back({std::filesystem::path(argv[i + 1]).stem().string(), argv[i + 1]});
  try {
    std::filesystem::create_directories(out);
    lionColors(data, out);
    textures(data, out);
    occlusion(occluded, out);
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-bench-appearance: {}\n", error.what());
    return 1;
  }
  return 0;
}
