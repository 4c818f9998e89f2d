// Pictures in and out of the viewer, through pipeline/io/image.h (OpenImageIO, or PNG and PPM files
// in builds without it): rendered frames written atomically (the format follows the file name's
// extension) and environment maps read from any image that reads.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

namespace iso::viewer {

// Write width × height pixels packed as RGBA8 (byte 0 red) to path: a complete new file or, on
// error, an iso::FileError and the old file untouched.
void writeImage(const std::filesystem::path& path, uint32_t width, uint32_t height,
                const std::vector<uint32_t>& rgba);

// Read an image as RGBA8 (for tests and comparisons); throws iso::FileError.
std::vector<uint32_t> readImage(const std::filesystem::path& path, uint32_t& width,
                                uint32_t& height);

// An equirectangular environment map as linear RGB in float16 pairs (2 words a texel: RG, B0),
// at most maxWidth wide (larger images are box-filtered down).
struct Environment {
  uint32_t width = 0, height = 0;
  std::vector<uint32_t> texels;
};
Environment loadEnvironment(const std::filesystem::path& path, uint32_t maxWidth = 2048);

}  // namespace iso::viewer
