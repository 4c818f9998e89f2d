// Images read through OpenImageIO as linear RGB: textures and environment maps.
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/vec3.hpp>
#include <vector>

namespace iso {

// Texels in rows from the top; linear RGB (8- and 16-bit images are sRGB-encoded and decoded,
// float images are linear already; gray images give gray, alpha is dropped).
struct LinearImage {
  uint32_t width = 0, height = 0;
  std::vector<glm::vec3> texels;
  const glm::vec3& at(uint32_t x, uint32_t y) const { return texels[size_t(y) * width + x]; }
};

// Read any image OpenImageIO reads, box-filtered down to at most maxWidth texels wide when it is
// wider (0: no limit). Throws iso::FileError naming the file for unreadable or empty images.
LinearImage readLinearImage(const std::filesystem::path& path, uint32_t maxWidth = 0);

// Open the image and read its header only: the same errors for files that are not images.
void checkImageReadable(const std::filesystem::path& path);

}  // namespace iso
