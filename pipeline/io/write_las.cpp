// LAS 1.2 output of points (ASPRS LAS Specification 1.2, 2008: §"Public Header Block", §"Point
// Data Record Format 0" and "2").
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <glm/common.hpp>

#include "iso/atomic_file.h"
#include "iso/error.h"
#include "iso/quantize.h"
#include "pipeline/io/las.h"

namespace iso {
namespace {

constexpr size_t kHeaderSize = 227;
constexpr size_t kChunkBytes = size_t{1} << 20;

template <typename T>
void putLE(std::byte* out, T value) {
  auto bytes = std::bit_cast<std::array<std::byte, sizeof(T)>>(value);
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes.begin(), bytes.end());
  std::memcpy(out, bytes.data(), sizeof(T));
}

}  // namespace

void writeLas(const std::filesystem::path& path, const PointCloud& points) {
  if (points.size() > std::numeric_limits<uint32_t>::max())
    throw FileError(path.string(), std::nullopt,
                    fmt::format("{} points: LAS 1.2 counts at most 4,294,967,295", points.size()));
  glm::dvec3 lo(0.0), hi(0.0);
  if (points.size() > 0) {
    lo = hi = points.positions[0];
    for (const glm::dvec3& p : points.positions) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
  }
  // Offset: the lower corner rounded down to whole units; scale: the finest power of ten whose
  // integers reach the far corner with a factor of two to spare.
  const glm::dvec3 offset = glm::floor(lo);
  const double range = std::max({hi.x - offset.x, hi.y - offset.y, hi.z - offset.z, 1e-300});
  const double scale = std::pow(10.0, std::ceil(std::log10(range / double(1 << 30))));
  if (!std::isfinite(scale) || !std::isfinite(range))
    throw FileError(path.string(), std::nullopt, "positions too large or not finite for LAS");

  const bool colors = points.hasColors();
  const uint16_t recordSize = colors ? 26 : 20;
  std::array<std::byte, kHeaderSize> header{};
  std::memcpy(header.data(), "LASF", 4);
  header[24] = std::byte{1};  // version 1.2
  header[25] = std::byte{2};
  const char software[] = "iso";
  std::memcpy(header.data() + 26, software, sizeof(software) - 1);  // system identifier
  std::memcpy(header.data() + 58, software, sizeof(software) - 1);  // generating software
  putLE<uint16_t>(header.data() + 94, uint16_t(kHeaderSize));
  putLE<uint32_t>(header.data() + 96, uint32_t(kHeaderSize));  // point data offset
  putLE<uint32_t>(header.data() + 100, 0);                     // no VLRs
  header[104] = std::byte{uint8_t(colors ? 2 : 0)};
  putLE<uint16_t>(header.data() + 105, recordSize);
  putLE<uint32_t>(header.data() + 107, uint32_t(points.size()));
  putLE<uint32_t>(header.data() + 111, uint32_t(points.size()));  // all first returns
  for (int axis = 0; axis < 3; ++axis) {
    putLE<double>(header.data() + 131 + 8 * axis, scale);
    putLE<double>(header.data() + 155 + 8 * axis, offset[axis]);
    putLE<double>(header.data() + 179 + 16 * axis, hi[axis]);
    putLE<double>(header.data() + 187 + 16 * axis, lo[axis]);
  }
  AtomicFile file(path);
  file.write(header);
  std::vector<std::byte> chunk;
  chunk.reserve(kChunkBytes + recordSize);
  for (size_t i = 0; i < points.size(); ++i) {
    std::byte record[26] = {};
    for (int axis = 0; axis < 3; ++axis)
      putLE<int32_t>(record + 4 * axis,
                     int32_t(std::llround((points.positions[i][axis] - offset[axis]) / scale)));
    record[14] = std::byte{0x09};  // return 1 of 1
    if (colors)
      for (int channel = 0; channel < 3; ++channel)
        putLE<uint16_t>(record + 20 + 2 * channel,
                        uint16_t(linearToSrgb8(points.colors[i][channel]) * 257));
    chunk.insert(chunk.end(), record, record + recordSize);
    if (chunk.size() >= kChunkBytes) {
      file.write(chunk);
      chunk.clear();
    }
  }
  file.write(chunk);
  file.commit();
}

}  // namespace iso
