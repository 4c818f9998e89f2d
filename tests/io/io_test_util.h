// Helpers for the reader and writer tests: files built byte by byte, gzip output, whole reads.
#pragma once

#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "iso/error.h"
#include "pipeline/io/readers.h"
#include "tests/support/support.h"

namespace iso::test {

// A file's content built byte by byte, little or big endian.
class Bytes {
 public:
  template <typename T>
  Bytes& le(T value) {
    return put(value, std::endian::little);
  }
  template <typename T>
  Bytes& be(T value) {
    return put(value, std::endian::big);
  }
  Bytes& text(std::string_view text) {
    for (char c : text) bytes_.push_back(static_cast<std::byte>(c));
    return *this;
  }
  Bytes& fill(size_t count, uint8_t value) {
    bytes_.insert(bytes_.end(), count, std::byte{value});
    return *this;
  }
  template <typename T>
  void patchLE(size_t at, T value) {
    auto raw = std::bit_cast<std::array<std::byte, sizeof(T)>>(value);
    if constexpr (std::endian::native == std::endian::big) std::reverse(raw.begin(), raw.end());
    std::copy(raw.begin(), raw.end(), bytes_.begin() + static_cast<ptrdiff_t>(at));
  }
  size_t size() const { return bytes_.size(); }
  const std::vector<std::byte>& bytes() const { return bytes_; }

 private:
  template <typename T>
  Bytes& put(T value, std::endian order) {
    auto raw = std::bit_cast<std::array<std::byte, sizeof(T)>>(value);
    if (order != std::endian::native) std::reverse(raw.begin(), raw.end());
    bytes_.insert(bytes_.end(), raw.begin(), raw.end());
    return *this;
  }

  std::vector<std::byte> bytes_;
};

inline void writeText(const std::filesystem::path& path, std::string_view text) {
  writeFile(path, Bytes().text(text).bytes());
}

// Write bytes gzip-compressed.
inline void writeGzip(const std::filesystem::path& path, const std::vector<std::byte>& bytes) {
  gzFile file = gzopen(path.c_str(), "wb");
  ASSERT_NE(file, nullptr);
  ASSERT_EQ(gzwrite(file, bytes.data(), static_cast<unsigned>(bytes.size())),
            static_cast<int>(bytes.size()));
  ASSERT_EQ(gzclose(file), Z_OK);
}

// Read a whole file through openPointFile in small batches, checking the batch contract.
inline PointCloud readInBatches(const std::filesystem::path& path, const ReadOptions& options = {},
                                ReadStats* stats = nullptr, size_t batch = 1000) {
  auto reader = openPointFile(path, options);
  PointCloud points;
  for (;;) {
    const size_t before = points.size();
    const size_t appended = reader->read(points, batch);
    EXPECT_LE(appended, batch);
    EXPECT_EQ(points.size(), before + appended);
    EXPECT_EQ(points.normals.size(), reader->info().hasNormals ? points.size() : 0u);
    EXPECT_EQ(points.colors.size(), reader->info().hasColors ? points.size() : 0u);
    if (appended == 0) break;
  }
  if (stats != nullptr) *stats = reader->stats();
  return points;
}

// The reason of the FileError that reading the whole file throws, or "" when none is thrown.
inline std::string readError(const std::filesystem::path& path, const ReadOptions& options = {}) {
  try {
    readPointFile(path, options);
  } catch (const FileError& error) {
    return error.what();
  }
  return "";
}

// The position rounded to float precision, as a file with float coordinates stores it. Through a
// volatile because GCC 12 at -O2 vectorizes (double)(float)x for two lanes and drops the rounding.
inline glm::dvec3 roundedToFloat(const glm::dvec3& p) {
  glm::dvec3 rounded;
  for (int axis = 0; axis < 3; ++axis) {
    volatile float single = static_cast<float>(p[axis]);
    rounded[axis] = single;
  }
  return rounded;
}

// The linear value of an 8-bit sRGB code, computed independently of the readers' table.
inline float linearOf8(int code) {
  const float c = static_cast<float>(code) / 255.0f;
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

}  // namespace iso::test
