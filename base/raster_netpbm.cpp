// Binary PGM and PPM files (raster.h), as Netpbm's format pages define them: a header of the magic
// number, width, height and maximum value in decimal, separated by white space and comments (from
// '#' to the end of the line), one white space character, then the samples.
#include <cstring>
#include <string>

#include "iso/check.h"
#include "iso/error.h"
#include "base/raster.h"

namespace iso {
namespace {

bool isSpace(std::byte b) {
  const char c = char(b);
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
}

// The header's next number from `at` on (moved past it), after white space and comments.
uint32_t headerNumber(std::span<const std::byte> bytes, size_t& at, const std::string& name,
                      const char* what) {
  while (at < bytes.size() && (isSpace(bytes[at]) || char(bytes[at]) == '#')) {
    if (char(bytes[at]) == '#')
      while (at < bytes.size() && char(bytes[at]) != '\n' && char(bytes[at]) != '\r') ++at;
    else
      ++at;
  }
  const size_t start = at;
  uint64_t value = 0;
  for (; at < bytes.size() && char(bytes[at]) >= '0' && char(bytes[at]) <= '9'; ++at) {
    value = value * 10 + uint64_t(char(bytes[at]) - '0');
    if (value > UINT32_MAX)
      throw FileError(name, start, std::string("the ") + what + " is too large");
  }
  if (at == start) throw FileError(name, start, std::string("the header has no ") + what);
  return uint32_t(value);
}

}  // namespace

bool looksLikeNetpbm(std::span<const std::byte> bytes) {
  return bytes.size() >= 2 && char(bytes[0]) == 'P' &&
         (char(bytes[1]) == '5' || char(bytes[1]) == '6');
}

Raster decodeNetpbm(std::span<const std::byte> bytes, const std::string& name) {
  if (!looksLikeNetpbm(bytes)) throw FileError(name, 0, "not a binary PGM (P5) or PPM (P6) file");
  Raster raster;
  raster.channels = char(bytes[1]) == '5' ? 1 : 3;
  size_t at = 2;
  raster.width = headerNumber(bytes, at, name, "width");
  raster.height = headerNumber(bytes, at, name, "height");
  const size_t maxAt = at;
  raster.maxValue = headerNumber(bytes, at, name, "maximum value");
  if (raster.width == 0 || raster.height == 0)
    throw FileError(name, std::nullopt, "the image is empty");
  if (raster.maxValue == 0 || raster.maxValue > 65535)
    throw FileError(name, maxAt, "the maximum value must be 1 to 65535");
  if (at >= bytes.size() || !isSpace(bytes[at]))
    throw FileError(name, at, "no white space after the header");
  ++at;
  const size_t sampleBytes = raster.maxValue > 255 ? 2 : 1;
  // width × height ≤ the pixels there are, without overflow.
  const uint64_t pixelsThere = (bytes.size() - at) / sampleBytes / raster.channels;
  if (raster.width > pixelsThere / raster.height)
    throw FileError(name, bytes.size(),
                    "the file ends inside the pixels of its " + std::to_string(raster.width) +
                        " × " + std::to_string(raster.height) + " image");
  raster.samples.resize(size_t(raster.width) * raster.height * raster.channels);
  for (uint16_t& sample : raster.samples) {
    sample = sampleBytes == 1 ? uint16_t(bytes[at])
                              : uint16_t(uint16_t(bytes[at]) << 8 | uint16_t(bytes[at + 1]));
    if (sample > raster.maxValue)
      throw FileError(name, at,
                      "a sample is above the maximum value " + std::to_string(raster.maxValue));
    at += sampleBytes;
  }
  return raster;
}

std::vector<std::byte> encodePpm(uint32_t width, uint32_t height, std::span<const uint32_t> rgba) {
  ISO_CHECK(rgba.size() == size_t(width) * height);
  const std::string header =
      "P6\n" + std::to_string(width) + " " + std::to_string(height) + "\n255\n";
  std::vector<std::byte> out(header.size() + rgba.size() * 3);
  std::memcpy(out.data(), header.data(), header.size());
  std::byte* p = out.data() + header.size();
  for (const uint32_t pixel : rgba)
    for (int c = 0; c < 3; ++c) *p++ = std::byte(pixel >> (8 * c) & 0xFF);
  return out;
}

}  // namespace iso
