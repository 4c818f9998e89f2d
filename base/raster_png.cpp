// PNG files through libpng's simplified interface (raster.h).
#include <png.h>

#include <bit>
#include <cstring>

#include "iso/check.h"
#include "iso/error.h"
#include "base/raster.h"

namespace iso {

bool looksLikePng(std::span<const std::byte> bytes) {
  static constexpr unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  return bytes.size() >= sizeof kSignature &&
         std::memcmp(bytes.data(), kSignature, sizeof kSignature) == 0;
}

Raster decodePng(std::span<const std::byte> bytes, const std::string& name) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  // On failure libpng has freed what it allocated; image.message says why.
  const auto fail = [&] {
    throw FileError(name, std::nullopt, std::string("cannot read the PNG image: ") + image.message);
  };
  if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size())) fail();
  image.format = PNG_FORMAT_RGBA;
  image.flags |= PNG_IMAGE_FLAG_16BIT_sRGB;  // as OpenImageIO takes them (image.h)
  Raster raster;
  raster.width = image.width;
  raster.height = image.height;
  raster.channels = 4;
  std::vector<uint8_t> pixels;
  try {
    pixels.resize(size_t(image.width) * image.height * 4);
  } catch (...) {
    png_image_free(&image);
    throw;
  }
  if (!png_image_finish_read(&image, nullptr, pixels.data(), 0, nullptr)) fail();
  raster.samples.assign(pixels.begin(), pixels.end());
  return raster;
}

std::vector<std::byte> encodePng(uint32_t width, uint32_t height, std::span<const uint32_t> rgba) {
  ISO_CHECK(rgba.size() == size_t(width) * height);
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = width;
  image.height = height;
  static_assert(std::endian::native == std::endian::little, "RGBA8 words are read as bytes");
  image.format = PNG_FORMAT_RGBA;
  png_alloc_size_t size = 0;
  if (!png_image_write_get_memory_size(image, size, 0, rgba.data(), 0, nullptr))
    throw std::runtime_error(std::string("cannot encode a PNG file: ") + image.message);
  std::vector<std::byte> out(size);
  if (!png_image_write_to_memory(&image, out.data(), &size, 0, rgba.data(), 0, nullptr))
    throw std::runtime_error(std::string("cannot encode a PNG file: ") + image.message);
  out.resize(size);
  return out;
}

}  // namespace iso
