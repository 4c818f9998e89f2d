// Images: textures and environment maps read as linear RGB, and pictures read and written as RGBA8.
// Through OpenImageIO (image_oiio.cpp: any format it knows), or, in builds without it
// (ISO_WITH_OPENIMAGEIO=OFF), through raster.h (image_raster.cpp): PNG and binary PPM/PGM files.
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

namespace iso {

// Texels in rows from the top; linear RGB (8- and 16-bit images are sRGB-encoded and decoded,
// float images are linear already; gray images give gray, alpha is dropped).
struct LinearImage {
  uint32_t width = 0, height = 0;
  std::vector<glm::vec3> texels;
  const glm::vec3& at(uint32_t x, uint32_t y) const { return texels[size_t(y) * width + x]; }
};

// Read an image, box-filtered down to at most maxWidth texels wide when it is wider (0: no
// limit). Throws iso::FileError naming the file for unreadable or empty images, and for images of
// a kind this build does not read.
LinearImage readLinearImage(const std::filesystem::path& path, uint32_t maxWidth = 0);

// Open the image and read its header only: the same errors for files that are not images.
void checkImageReadable(const std::filesystem::path& path);

// Throw iso::UsageError, naming `option`, when this build writes no image of the kind path's
// extension names: before any work is done for it.
void checkImageWritable(const std::filesystem::path& path, const std::string& option);

// Write width × height pixels packed as RGBA8 (byte 0 red, rows from the top) in the format path's
// extension names: a complete new file or, on error, an iso::FileError and the old file untouched.
void writeRgba8Image(const std::filesystem::path& path, uint32_t width, uint32_t height,
                     const std::vector<uint32_t>& rgba);

// Read an image as RGBA8 (gray expanded, alpha 255 where it has none). Throws iso::FileError.
std::vector<uint32_t> readRgba8Image(const std::filesystem::path& path, uint32_t& width,
                                     uint32_t& height);

// An equirectangular environment map as linear RGB in float16 pairs (2 words a texel: RG, B0),
// at most maxWidth wide (larger images are box-filtered down): what the tracers read.
struct Environment {
  uint32_t width = 0, height = 0;
  std::vector<uint32_t> texels;
};
Environment loadEnvironment(const std::filesystem::path& path, uint32_t maxWidth = 2048);

}  // namespace iso
