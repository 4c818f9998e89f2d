// PNG (libpng) and binary PGM/PPM images in memory: the pictures of builds without OpenImageIO
// (image.h, ISO_WITH_OPENIMAGEIO=OFF), compiled in every build so that tests hold them to
// OpenImageIO's reading. The decoders are safe for untrusted bytes: a malformed image throws.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace iso {

// Pixels as a file stores them: rows from the top, `channels` samples a pixel (1 gray, 3 RGB,
// 4 RGBA), each from 0 to maxValue (255 for 8-bit samples; at most 65535).
struct Raster {
  uint32_t width = 0, height = 0, channels = 0, maxValue = 255;
  std::vector<uint16_t> samples;
};

// Whether the bytes start as a PNG file does, or as a binary PGM (P5) or PPM (P6) file.
bool looksLikePng(std::span<const std::byte> bytes);
bool looksLikeNetpbm(std::span<const std::byte> bytes);

// A PNG file as 8-bit RGBA (libpng's simplified reader: gray and palettes expanded, other gammas
// converted to sRGB, 16-bit samples taken as sRGB-encoded and rounded to 8 bits). Throws
// iso::FileError naming `name` when libpng cannot read it.
Raster decodePng(std::span<const std::byte> bytes, const std::string& name);

// A binary PGM (P5: 1 channel) or PPM (P6: 3 channels) file, samples as stored: 1 byte each up to
// a maximum value of 255, 2 big-endian bytes above. Throws iso::FileError naming `name`, with the
// byte offset where the file goes wrong.
Raster decodeNetpbm(std::span<const std::byte> bytes, const std::string& name);

// width × height pixels packed as RGBA8 (byte 0 red, rows from the top) as a PNG file (alpha kept)
// or a binary PPM file (P6, alpha dropped). rgba holds width × height pixels.
std::vector<std::byte> encodePng(uint32_t width, uint32_t height, std::span<const uint32_t> rgba);
std::vector<std::byte> encodePpm(uint32_t width, uint32_t height, std::span<const uint32_t> rgba);

}  // namespace iso
