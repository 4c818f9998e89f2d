// iso-bench-build [--points N,N,...] [--shape NAME] [--no-normals] [--dir D]: speed of the in-core
// ISO construction. For each size, samples the shape (in memory, not timed), converts it with the
// default options and prints seconds and points/s per stage, the total, peak memory, bytes per
// leaf and per point, and the accuracy the conversion reports. Points/s of the stages are
// comparable within one run; the machine's other load is not controlled.
#include <fmt/core.h>

#include <chrono>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "pipeline/base/options.h"
#include "pipeline/convert/convert.h"
#include "pipeline/geom/generate.h"
#include "pipeline/geom/shape.h"

namespace {

struct Config {
  std::vector<uint64_t> sizes = {1000000, 10000000};
  std::string shape = "sphere";
  bool normals = true;
  std::filesystem::path dir = std::filesystem::temp_directory_path();
};

std::vector<uint64_t> parseSizes(const std::string& text) {
  std::vector<uint64_t> sizes;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) sizes.push_back(std::stoull(item));
  return sizes;
}

void run(const Config& config, uint64_t count) {
  iso::ShapeParams params;
  params.name = config.shape;
  const std::unique_ptr<iso::Shape> shape = iso::makeShape(params);
  iso::GenerateOptions generate;
  generate.count = count;
  generate.normals = config.normals;
  const iso::PointCloud points = iso::generateScan(*shape, generate);
  const std::filesystem::path output = config.dir / "iso-bench-build.iso";
  const nlohmann::json r = iso::convertToIso(points, output, iso::BuildOptions{});
  std::filesystem::remove(output);
  fmt::print("\n{} points of a {} ({} normals)\n", count, config.shape,
             config.normals ? "with" : "without");
  fmt::print("  {:<18} {:>9} {:>14}\n", "stage", "seconds", "points/s");
  for (const auto& s : r["stages"]) {
    const double seconds = s["seconds"].get<double>();
    fmt::print("  {:<18} {:>9.3f} {:>14.0f}\n", s["name"].get<std::string>(), seconds,
               double(count) / seconds);
  }
  fmt::print("  {:<18} {:>9.3f} {:>14.0f}\n", "total", r["seconds"].get<double>(),
             r["points_per_second"].get<double>());
  fmt::print(
      "  peak RSS {:.0f} MiB; {} leaves; {:.2f} bytes/leaf, {:.3f} bytes/point; "
      "accuracy RMS {:.3f}, max {:.3f} spacings\n",
      double(r["peak_rss_bytes"].get<uint64_t>()) / 1048576.0,
      r["octree"]["leaves"].get<uint64_t>(), r["file"]["bytes_per_leaf"].get<double>(),
      r["file"]["bytes_per_point"].get<double>(), r["accuracy"]["rms_over_spacing"].get<double>(),
      r["accuracy"]["max_over_spacing"].get<double>());
}

}  // namespace

int main(int argc, char** argv) {
  Config config;
  const char* usage =
      "usage: iso-bench-build [--points N,N,...] [--shape NAME] [--no-normals] [--dir D]\n";
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string option = argv[i];
      if (option == "--no-normals") {
        config.normals = false;
      } else if (i + 1 < argc && option == "--points") {
        config.sizes = parseSizes(argv[++i]);
      } else if (i + 1 < argc && option == "--shape") {
        config.shape = argv[++i];
      } else if (i + 1 < argc && option == "--dir") {
        config.dir = argv[++i];
      } else {
        fmt::print(stderr, "{}", usage);
        return 2;
      }
    }
    fmt::print(
        "in-core ISO construction benchmark (default options; stage times from the conversion "
        "report)\n");
    for (uint64_t count : config.sizes) run(config, count);
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-bench-build: {}\n", error.what());
    return 1;
  }
  return 0;
}
