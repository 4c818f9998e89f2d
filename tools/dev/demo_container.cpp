// iso-demo-container IN.xyz OUT.iso: pack a point file ("x y z [nx ny nz]" per line) into an .iso
// container: one blob chunk per occupied octree cell at level 2 holding that cell's points, under
// a level-0 chunk holding every 16th point as a coarse preview. It shows the container (frame in
// double, chunk hierarchy, zstd, metadata) on real data until `iso convert` builds surfaces.
#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "iso/error.h"
#include "iso/writer.h"

namespace {

struct Point {
  std::array<double, 3> position;
  std::array<float, 3> normal;
};

std::vector<Point> readXyz(const std::string& path, bool& hasNormals) {
  std::ifstream in(path);
  if (!in) throw iso::FileError(path, std::nullopt, "cannot open");
  std::vector<Point> points;
  std::string line;
  hasNormals = true;
  for (int lineNumber = 1; std::getline(in, line); ++lineNumber) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    Point p{};
    double v[6];
    int count = 0;
    while (count < 6 && fields >> v[count]) ++count;
    if (count != 3 && count != 6)
      throw iso::FileError(
          path, std::nullopt,
          fmt::format("line {}: expected 3 or 6 numbers, found {}", lineNumber, count));
    for (int i = 0; i < count; ++i)
      if (!std::isfinite(v[i]))
        throw iso::FileError(path, std::nullopt,
                             fmt::format("line {}: a value is not finite", lineNumber));
    for (int i = 0; i < 3; ++i) p.position[i] = v[i];
    for (int i = 0; i < 3 && count == 6; ++i) p.normal[i] = static_cast<float>(v[3 + i]);
    hasNormals = hasNormals && count == 6;
    points.push_back(p);
  }
  if (points.empty()) throw iso::FileError(path, std::nullopt, "no points");
  return points;
}

// The smallest cube around the points, grown by 1% so that no point lies on its upper faces.
iso::Frame boundingFrame(const std::vector<Point>& points) {
  std::array<double, 3> lo = points[0].position, hi = points[0].position;
  for (const Point& p : points)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p.position[a]);
      hi[a] = std::max(hi[a], p.position[a]);
    }
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-9});
  iso::Frame frame;
  frame.size = extent * 1.01;
  for (int a = 0; a < 3; ++a) frame.origin[a] = lo[a] - 0.005 * extent;
  return frame;
}

uint64_t mortonKey(const std::array<uint32_t, 3>& cell, int level) {
  uint64_t key = 0;
  for (int bit = 0; bit < level; ++bit)
    for (int axis = 0; axis < 3; ++axis)
      key |= uint64_t((cell[axis] >> bit) & 1u) << (3 * bit + axis);
  return key;
}

// Frame-local float32 positions (and normals) of the points, little endian.
std::vector<std::byte> packPoints(const std::vector<const Point*>& points, const iso::Frame& frame,
                                  bool hasNormals) {
  std::vector<float> values;
  for (const Point* p : points) {
    for (int a = 0; a < 3; ++a)
      values.push_back(static_cast<float>((p->position[a] - frame.origin[a]) / frame.size));
    if (hasNormals) values.insert(values.end(), p->normal.begin(), p->normal.end());
  }
  const auto bytes = std::as_bytes(std::span(values));
  return {bytes.begin(), bytes.end()};
}

int run(const std::string& inputPath, const std::string& outputPath) {
  bool hasNormals = false;
  const std::vector<Point> points = readXyz(inputPath, hasNormals);
  const iso::Frame frame = boundingFrame(points);
  constexpr int kLevel = 2;

  std::map<uint64_t, std::vector<const Point*>> cells;
  std::vector<const Point*> preview;
  for (size_t i = 0; i < points.size(); ++i) {
    std::array<uint32_t, 3> cell{};
    for (int a = 0; a < 3; ++a) {
      const double u = (points[i].position[a] - frame.origin[a]) / frame.size;
      cell[a] = std::min<uint32_t>((1u << kLevel) - 1,
                                   static_cast<uint32_t>(std::max(0.0, u) * (1 << kLevel)));
    }
    cells[mortonKey(cell, kLevel)].push_back(&points[i]);
    if (i % 16 == 0) preview.push_back(&points[i]);
  }

  iso::FileHeader header;
  header.frame = frame;
  header.maxLevel = kLevel;
  iso::Writer writer(outputPath, header);
  iso::ChunkDesc root;
  root.pointCount = points.size();
  const uint32_t rootId = writer.addChunk(root, packPoints(preview, frame, hasNormals));
  for (const auto& [key, cellPoints] : cells) {
    iso::ChunkDesc desc;
    desc.level = kLevel;
    desc.key = key;
    desc.parent = rootId;
    desc.pointCount = cellPoints.size();
    writer.addChunk(desc, packPoints(cellPoints, frame, hasNormals));
  }
  nlohmann::json metadata = {
      {"generator", "iso-demo-container"},
      {"inputs", {inputPath}},
      {"blob_layout", hasNormals ? "float32 x y z nx ny nz per point; positions in frame units"
                                 : "float32 x y z per point; positions in frame units"},
      {"note", "points packed into chunks by octree cell; no surface yet"}};
  writer.setMetadata(metadata.dump());
  writer.finish();
  fmt::print("wrote {}: {} points in {} chunks ({} bytes)\n", outputPath, points.size(),
             writer.chunkCount(), writer.bytesWritten());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    fmt::print(stderr, "usage: iso-demo-container IN.xyz OUT.iso\n");
    return 2;
  }
  try {
    return run(argv[1], argv[2]);
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-demo-container: {}\n", error.what());
    return 1;
  }
}
