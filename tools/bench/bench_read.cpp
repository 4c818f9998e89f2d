// iso-bench-read SCAN.las DIR [--repeat N]: every reader's speed on the same points. The points
// of SCAN (LAS 1.0-1.3, point format 0: `iso gen --mesh ... -o SCAN.las`) are written once into
// DIR as LAS (the scan itself), LAZ (LASzip chunks of 50,000 points, tests/support/laz_writer.h),
// PLY binary (double positions) and ASCII, PCD binary (float), text (x y z, 4 decimals), E57
// (double cartesian, one scan) and Draco (20-bit positions), unless they are there already. Then
// each is read N times (default 3) through openPointFile as `iso convert` reads it (batches of
// 2^20 points into one reused cloud), and the fastest run is printed: seconds, points/s, MB/s of
// file, bytes a point, and the ratio to LAS.
//
// iso-bench-read --write-e57 SCAN.las OUT.e57: the points as an E57 file of a terrestrial
// scanner's fields (double cartesian coordinates, a float intensity, 8-bit colors, a double time
// stamp, 16-bit row and column indices: 43 bytes a point).
// iso-bench-read --peak FILE: read FILE as above, once; print its points, seconds and this
// process's peak memory.
#include <draco/compression/encode.h>
#include <draco/point_cloud/point_cloud_builder.h>
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "iso/error.h"
#include "pipeline/base/process.h"
#include "pipeline/io/laz_decoder.h"
#include "pipeline/io/ply.h"
#include "pipeline/io/readers.h"
#include "tests/support/e57_file.h"
#include "tests/support/laz_writer.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A file written through a temporary name, so that an interrupted run leaves none half written.
template <typename Write>
void writeOnce(const fs::path& path, Write write) {
  if (fs::exists(path)) return;
  const fs::path temporary = path.string() + ".part";
  fmt::print(stderr, "bench read: writing {}\n", path.filename().string());
  write(temporary);
  fs::rename(temporary, path);
}

void writeText(const fs::path& path, const iso::PointCloud& points) {
  std::FILE* file = std::fopen(path.c_str(), "w");
  if (file == nullptr) throw iso::FileError(path.string(), std::nullopt, "cannot write");
  for (const glm::dvec3& p : points.positions)
    fmt::print(file, "{:.4f} {:.4f} {:.4f}\n", p.x, p.y, p.z);
  std::fclose(file);
}

void writePcd(const fs::path& path, const iso::PointCloud& points) {
  std::ofstream out(path, std::ios::binary);
  out << fmt::format(
      "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n"
      "TYPE F F F\nCOUNT 1 1 1\nWIDTH {0}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {0}\n"
      "DATA binary\n",
      points.size());
  const glm::dvec3 origin = points.positions.empty() ? glm::dvec3(0) : points.positions[0];
  for (const glm::dvec3& p : points.positions) {
    const glm::vec3 local(p - origin);  // PCD is float: near the origin, as PCL writes scans
    out.write(reinterpret_cast<const char*>(&local), sizeof local);
  }
}

void writeDraco(const fs::path& path, const iso::PointCloud& points) {
  draco::PointCloudBuilder builder;
  builder.Start(uint32_t(points.size()));
  const int attribute =
      builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  const glm::dvec3 origin = points.positions.empty() ? glm::dvec3(0) : points.positions[0];
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::vec3 local(points.positions[i] - origin);
    builder.SetAttributeValueForPoint(attribute, draco::PointIndex(uint32_t(i)), &local);
  }
  const std::unique_ptr<draco::PointCloud> cloud = builder.Finalize(false);
  draco::Encoder encoder;
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, 20);
  draco::EncoderBuffer buffer;
  if (!encoder.EncodePointCloudToBuffer(*cloud, &buffer).ok())
    throw iso::FileError(path.string(), std::nullopt, "Draco cannot encode the points");
  std::ofstream(path, std::ios::binary).write(buffer.data(), std::streamsize(buffer.size()));
}

// An E57 file of one scan: double cartesian coordinates and, with `scannerFields`, what a
// terrestrial scanner adds (values made up from the position and the index).
void writeE57(const fs::path& path, const iso::PointCloud& points, bool scannerFields = false) {
  using iso::test::E57FieldSpec;
  using iso::test::E57Type;
  iso::test::E57ScanSpec scan;
  scan.name = "scan";
  for (int axis = 0; axis < 3; ++axis) {
    E57FieldSpec field{.name = std::string("cartesian") + char('X' + axis)};
    field.floats.reserve(points.size());
    for (const glm::dvec3& p : points.positions) field.floats.push_back(p[axis]);
    scan.fields.push_back(std::move(field));
  }
  if (scannerFields) {
    const size_t n = points.size();
    const auto integers = [&](const char* name, int64_t maximum, auto value) {
      E57FieldSpec field{.name = name, .type = E57Type::kInteger, .minimum = 0, .maximum = maximum};
      field.integers.resize(n);
      for (size_t i = 0; i < n; ++i) field.integers[i] = value(i);
      scan.fields.push_back(std::move(field));
    };
    E57FieldSpec intensity{.name = "intensity", .type = E57Type::kSingle};
    intensity.attributes = R"( minimum="0" maximum="1")";
    intensity.floats.resize(n);
    for (size_t i = 0; i < n; ++i) intensity.floats[i] = double(i % 1000) / 1000.0;
    scan.fields.push_back(std::move(intensity));
    for (int c = 0; c < 3; ++c)
      integers(c == 0   ? "colorRed"
               : c == 1 ? "colorGreen"
                        : "colorBlue",
               255, [&](size_t i) {
                 return int64_t(std::fmod(std::abs(points.positions[i][c]) * 997.0, 256.0));
               });
    E57FieldSpec time{.name = "timeStamp"};
    time.floats.resize(n);
    for (size_t i = 0; i < n; ++i) time.floats[i] = 1e5 + double(i) * 1e-6;
    scan.fields.push_back(std::move(time));
    integers("rowIndex", 65535, [](size_t i) { return int64_t(i % 65536); });
    integers("columnIndex", 65535, [](size_t i) { return int64_t((i / 65536) % 65536); });
  }
  iso::test::E57Spec spec;
  spec.scans.push_back(std::move(scan));
  const std::vector<std::byte> bytes = iso::test::makeE57(spec);
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

struct Timing {
  double seconds = 0.0;
  uint64_t points = 0;
};

// Read a file as `iso convert` does, the fastest of `repeat` runs.
Timing timeRead(const fs::path& path, int repeat) {
  Timing best;
  for (int run = 0; run < repeat; ++run) {
    const auto start = Clock::now();
    const std::unique_ptr<iso::PointReader> reader = iso::openPointFile(path);
    iso::PointCloud batch;
    uint64_t points = 0;
    for (;;) {
      batch.clear();
      const size_t read = reader->read(batch, size_t{1} << 20);
      if (read == 0) break;
      points += read;
    }
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    if (run == 0 || seconds < best.seconds) best = {seconds, points};
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "--peak") {
    const Timing t = timeRead(argv[2], 1);
    fmt::print("{}: {} points in {:.2f} s, peak memory {:.0f} MiB\n", argv[2], t.points, t.seconds,
               double(iso::peakRssBytes()) / (1 << 20));
    return 0;
  }
  if (argc == 4 && std::string(argv[1]) == "--write-e57") {
    writeOnce(argv[3], [&](const fs::path& p) { writeE57(p, iso::readPointFile(argv[2]), true); });
    return 0;
  }
  if (argc < 3) {
    fmt::print(stderr,
               "usage: iso-bench-read SCAN.las DIR [--repeat N]\n"
               "       iso-bench-read --write-e57 SCAN.las OUT.e57\n"
               "       iso-bench-read --peak FILE\n");
    return 2;
  }
  const fs::path scan = argv[1], dir = argv[2];
  int repeat = 3;
  for (int i = 3; i + 1 < argc; i += 2)
    if (std::string(argv[i]) == "--repeat") repeat = std::max(1, std::atoi(argv[i + 1]));
  try {
    fs::create_directories(dir);
    const std::string stem = scan.stem().string();
    const auto file = [&](const char* extension) { return dir / (stem + extension); };
    iso::PointCloud points;
    const auto loaded = [&]() -> const iso::PointCloud& {
      if (points.size() == 0) points = iso::readPointFile(scan);
      return points;
    };
    writeOnce(file(".laz"), [&](const fs::path& p) { iso::bench::writeLazFromLas(scan, p); });
    writeOnce(file(".bin.ply"), [&](const fs::path& p) { iso::writePly(p, loaded()); });
    writeOnce(file(".ascii.ply"),
              [&](const fs::path& p) { iso::writePly(p, loaded(), {.binary = false}); });
    writeOnce(file(".pcd"), [&](const fs::path& p) { writePcd(p, loaded()); });
    writeOnce(file(".xyz"), [&](const fs::path& p) { writeText(p, loaded()); });
    writeOnce(file(".e57"), [&](const fs::path& p) { writeE57(p, loaded()); });
    writeOnce(file(".drc"), [&](const fs::path& p) { writeDraco(p, loaded()); });
    points = {};
    const std::vector<std::pair<std::string, fs::path>> inputs = {
        {"LAS 1.2 format 0", scan},
        {"LAZ (laz-perf, 50k chunks)", file(".laz")},
        {"PLY binary (double)", file(".bin.ply")},
        {"PLY ASCII", file(".ascii.ply")},
        {"PCD binary (float)", file(".pcd")},
        {"text x y z", file(".xyz")},
        {"E57 (double)", file(".e57")},
        {"Draco (20 bits)", file(".drc")}};
    fmt::print("{} points of {}, the fastest of {} reads; LAZ decoded on {} threads\n",
               iso::openPointFile(scan)->info().declaredPoints.value_or(0),
               scan.filename().string(), repeat, std::thread::hardware_concurrency());
    fmt::print("  {:<28} {:>10} {:>9} {:>13} {:>9} {:>11} {:>9}\n", "format", "MB", "seconds",
               "points/s", "MB/s", "bytes/point", "vs LAS");
    double lasSeconds = 0.0;
    for (const auto& [name, path] : inputs) {
      const Timing t = timeRead(path, repeat);
      if (lasSeconds == 0.0) lasSeconds = t.seconds;
      const double megabytes = double(fs::file_size(path)) / 1e6;
      fmt::print("  {:<28} {:>10.1f} {:>9.3f} {:>13.0f} {:>9.1f} {:>11.2f} {:>8.2f}x\n", name,
                 megabytes, t.seconds, double(t.points) / t.seconds, megabytes / t.seconds,
                 megabytes * 1e6 / double(t.points), t.seconds / lasSeconds);
    }
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-bench-read: {}\n", error.what());
    return 1;
  }
  return 0;
}
