// PLY output of points and triangle meshes, written atomically.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "iso/atomic_file.h"
#include "iso/check.h"
#include "pipeline/io/color.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/ply.h"

namespace iso {
namespace {

// Bytes gathered before each write to the output file.
constexpr size_t kChunkBytes = size_t{1} << 20;

template <typename T>
void appendLE(std::vector<std::byte>& out, T value) {
  auto bytes = std::bit_cast<std::array<std::byte, sizeof(T)>>(value);
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes.begin(), bytes.end());
  out.insert(out.end(), bytes.begin(), bytes.end());
}

// Shortest text that reads back as the same value.
template <typename T>
void appendNumber(std::string& out, T value) {
  char text[32];
  const auto result = std::to_chars(text, text + sizeof(text), value);
  out.append(text, result.ptr);
}

std::string pointHeader(uint64_t count, bool normals, bool colors, const PlyWriteOptions& options) {
  std::string header = "ply\n";
  header += options.binary ? "format binary_little_endian 1.0\n" : "format ascii 1.0\n";
  for (std::string comment : options.comments) {
    std::replace(comment.begin(), comment.end(), '\n', ' ');
    std::replace(comment.begin(), comment.end(), '\r', ' ');
    header += "comment " + comment + "\n";
  }
  header += fmt::format("element vertex {}\n", count);
  const char* positionType = options.doublePositions ? "double" : "float";
  for (const char* axis : {"x", "y", "z"})
    header += fmt::format("property {} {}\n", positionType, axis);
  if (normals) header += "property float nx\nproperty float ny\nproperty float nz\n";
  if (colors) header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  for (const std::string& name : options.extraNames)
    header += fmt::format("property double {}\n", name);
  return header + "end_header\n";
}

void writeBinaryPoints(AtomicFile& file, const PointCloud& points, bool doublePositions,
                       size_t extras) {
  std::vector<std::byte> chunk;
  chunk.reserve(kChunkBytes + 64);
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::dvec3& p = points.positions[i];
    if (doublePositions) {
      for (int axis = 0; axis < 3; ++axis) appendLE(chunk, p[axis]);
    } else {
      for (int axis = 0; axis < 3; ++axis) appendLE(chunk, io::narrowToFloat(p[axis]));
    }
    if (points.hasNormals())
      for (int axis = 0; axis < 3; ++axis) appendLE(chunk, points.normals[i][axis]);
    if (points.hasColors())
      for (int channel = 0; channel < 3; ++channel)
        appendLE(chunk, linearToSrgb8(points.colors[i][channel]));
    for (size_t e = 0; e < extras; ++e) appendLE(chunk, points.extras[i * extras + e]);
    if (chunk.size() >= kChunkBytes) {
      file.write(chunk);
      chunk.clear();
    }
  }
  file.write(chunk);
}

void writeAsciiPoints(AtomicFile& file, const PointCloud& points, bool doublePositions,
                      size_t extras) {
  std::string chunk;
  chunk.reserve(kChunkBytes + 256);
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::dvec3& p = points.positions[i];
    for (int axis = 0; axis < 3; ++axis) {
      if (axis > 0) chunk += ' ';
      if (doublePositions) {
        appendNumber(chunk, p[axis]);
      } else {
        appendNumber(chunk, io::narrowToFloat(p[axis]));
      }
    }
    if (points.hasNormals())
      for (int axis = 0; axis < 3; ++axis) {
        chunk += ' ';
        appendNumber(chunk, points.normals[i][axis]);
      }
    if (points.hasColors())
      for (int channel = 0; channel < 3; ++channel) {
        chunk += ' ';
        appendNumber(chunk, int{linearToSrgb8(points.colors[i][channel])});
      }
    for (size_t e = 0; e < extras; ++e) {
      chunk += ' ';
      appendNumber(chunk, points.extras[i * extras + e]);
    }
    chunk += '\n';
    if (chunk.size() >= kChunkBytes) {
      file.write(chunk);
      chunk.clear();
    }
  }
  file.write(chunk);
}

}  // namespace

PlyPointWriter::PlyPointWriter(const std::filesystem::path& path, uint64_t count, bool normals,
                               bool colors, const PlyWriteOptions& options)
    : file_(std::make_unique<AtomicFile>(path)),
      options_(options),
      count_(count),
      normals_(normals),
      colors_(colors) {
  file_->write(pointHeader(count, normals, colors, options));
}

PlyPointWriter::~PlyPointWriter() = default;

void PlyPointWriter::write(const PointCloud& points) {
  ISO_CHECK(points.hasNormals() == normals_ && points.hasColors() == colors_);
  ISO_CHECK(points.normals.empty() || points.normals.size() == points.size());
  ISO_CHECK(points.colors.empty() || points.colors.size() == points.size());
  ISO_CHECK(written_ + points.size() <= count_);
  const size_t extras = options_.extraNames.size();
  ISO_CHECK(extras == 0 || (points.extraNames == options_.extraNames &&
                            points.extras.size() == points.size() * extras));
  if (options_.binary) {
    writeBinaryPoints(*file_, points, options_.doublePositions, extras);
  } else {
    writeAsciiPoints(*file_, points, options_.doublePositions, extras);
  }
  written_ += points.size();
}

void PlyPointWriter::commit() {
  ISO_CHECK(written_ == count_);
  file_->commit();
}

void writePly(const std::filesystem::path& path, const PointCloud& points,
              const PlyWriteOptions& options) {
  PlyPointWriter writer(path, points.size(), points.hasNormals(), points.hasColors(), options);
  writer.write(points);
  writer.commit();
}

void writePlyMesh(const std::filesystem::path& path, const TriangleMesh& mesh,
                  bool doublePositions) {
  // Indices are written as PLY "int", so every vertex must be reachable by a signed 32-bit index.
  ISO_CHECK(mesh.vertices.size() <= size_t{std::numeric_limits<int32_t>::max()} + 1);
  AtomicFile file(path);
  file.write(
      fmt::format("ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty {} x\n"
                  "property {} y\nproperty {} z\nelement face {}\n"
                  "property list uchar int vertex_indices\nend_header\n",
                  mesh.vertices.size(), doublePositions ? "double" : "float",
                  doublePositions ? "double" : "float", doublePositions ? "double" : "float",
                  mesh.triangles.size()));
  std::vector<std::byte> chunk;
  chunk.reserve(kChunkBytes + 64);
  const auto flushIfFull = [&] {
    if (chunk.size() < kChunkBytes) return;
    file.write(chunk);
    chunk.clear();
  };
  for (const glm::dvec3& v : mesh.vertices) {
    for (int axis = 0; axis < 3; ++axis) {
      if (doublePositions)
        appendLE(chunk, v[axis]);
      else
        appendLE(chunk, io::narrowToFloat(v[axis]));
    }
    flushIfFull();
  }
  for (const std::array<uint32_t, 3>& triangle : mesh.triangles) {
    appendLE(chunk, uint8_t{3});
    for (uint32_t index : triangle) {
      ISO_CHECK(index < mesh.vertices.size());
      appendLE(chunk, static_cast<int32_t>(index));
    }
    flushIfFull();
  }
  file.write(chunk);
  file.commit();
}

}  // namespace iso
