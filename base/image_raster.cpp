// Images without OpenImageIO (image.h): the builds with ISO_WITH_OPENIMAGEIO=OFF read PNG and
// binary PGM/PPM files and write .png and .ppm pictures, through raster.h.
#include <algorithm>
#include <cctype>
#include <fstream>

#include "iso/atomic_file.h"
#include "iso/error.h"
#include "iso/quantize.h"
#include "base/image.h"
#include "base/raster.h"

namespace iso {
namespace {

const char* const kReads =
    "not a PNG or binary PPM/PGM image, the only ones this build of iso reads (it has no "
    "OpenImageIO)";

std::vector<std::byte> fileBytes(const std::filesystem::path& path) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error))
    throw FileError(path.string(), std::nullopt, "no such image file");
  const uintmax_t size = std::filesystem::file_size(path, error);
  std::ifstream in(path, std::ios::binary);
  if (error || !in) throw FileError(path.string(), std::nullopt, "cannot open the image");
  std::vector<std::byte> bytes(size);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size())))
    throw FileError(path.string(), std::nullopt, "cannot read the image");
  return bytes;
}

Raster readRaster(const std::filesystem::path& path) {
  const std::vector<std::byte> bytes = fileBytes(path);
  if (looksLikePng(bytes)) return decodePng(bytes, path.string());
  if (looksLikeNetpbm(bytes)) return decodeNetpbm(bytes, path.string());
  throw FileError(path.string(), std::nullopt, std::string("cannot read the image: ") + kReads);
}

// The format a picture's name asks for: "png", "ppm", or "" for one this build does not write.
std::string writtenFormat(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  if (extension == ".png") return "png";
  if (extension == ".ppm") return "ppm";
  return "";
}

// Each texel the mean of the source texels it covers (the source is wider than `width`).
LinearImage boxFilteredDown(const LinearImage& in, uint32_t width) {
  LinearImage out;
  out.width = width;
  out.height = std::max<uint32_t>(1, uint32_t(uint64_t(in.height) * width / in.width));
  out.texels.resize(size_t(out.width) * out.height);
  const auto span = [](uint32_t i, uint32_t from, uint32_t to) {
    const uint32_t lo = uint32_t(uint64_t(i) * from / to);
    return std::pair(lo, std::max(lo + 1, uint32_t(uint64_t(i + 1) * from / to)));
  };
  for (uint32_t y = 0; y < out.height; ++y) {
    const auto [y0, y1] = span(y, in.height, out.height);
    for (uint32_t x = 0; x < out.width; ++x) {
      const auto [x0, x1] = span(x, in.width, out.width);
      glm::vec3 sum(0.0f);
      for (uint32_t v = y0; v < y1; ++v)
        for (uint32_t u = x0; u < x1; ++u) sum += in.at(u, v);
      out.texels[size_t(y) * out.width + x] = sum / float((y1 - y0) * (x1 - x0));
    }
  }
  return out;
}

}  // namespace

void checkImageReadable(const std::filesystem::path& path) { readRaster(path); }

LinearImage readLinearImage(const std::filesystem::path& path, uint32_t maxWidth) {
  const Raster raster = readRaster(path);
  LinearImage image;
  image.width = raster.width;
  image.height = raster.height;
  image.texels.resize(size_t(raster.width) * raster.height);
  const auto linear = [&](uint16_t sample) {
    return srgbToLinear(float(sample) / float(raster.maxValue));
  };
  for (size_t i = 0; i < image.texels.size(); ++i) {
    const uint16_t* p = &raster.samples[i * raster.channels];
    const bool gray = raster.channels < 3;
    image.texels[i] = {linear(p[0]), linear(gray ? p[0] : p[1]), linear(gray ? p[0] : p[2])};
  }
  if (maxWidth > 0 && image.width > maxWidth) return boxFilteredDown(image, maxWidth);
  return image;
}

void checkImageWritable(const std::filesystem::path& path, const std::string& option) {
  if (writtenFormat(path).empty())
    throw UsageError(option + ": " + path.string() +
                     ": this build of iso has no OpenImageIO: it writes .png and .ppm pictures "
                     "only");
}

void writeRgba8Image(const std::filesystem::path& path, uint32_t width, uint32_t height,
                     const std::vector<uint32_t>& rgba) {
  const std::string format = writtenFormat(path);
  if (format.empty())
    throw FileError(path.string(), std::nullopt,
                    "cannot write this kind of image: this build of iso has no OpenImageIO and "
                    "writes .png and .ppm pictures only");
  const std::vector<std::byte> bytes =
      format == "png" ? encodePng(width, height, rgba) : encodePpm(width, height, rgba);
  AtomicFile file(path);
  file.write(bytes);
  file.commit();
}

std::vector<uint32_t> readRgba8Image(const std::filesystem::path& path, uint32_t& width,
                                     uint32_t& height) {
  const Raster raster = readRaster(path);
  width = raster.width;
  height = raster.height;
  const auto byte = [&](uint16_t sample) {
    return (uint32_t(sample) * 255 + raster.maxValue / 2) / raster.maxValue;
  };
  std::vector<uint32_t> out(size_t(width) * height);
  const uint32_t n = raster.channels;
  for (size_t i = 0; i < out.size(); ++i) {
    const uint16_t* p = &raster.samples[i * n];
    const uint32_t r = byte(p[0]), g = n > 1 ? byte(p[1]) : r, b = n > 2 ? byte(p[2]) : r,
                   a = n > 3 ? byte(p[3]) : 255;
    out[i] = r | g << 8 | b << 16 | a << 24;
  }
  return out;
}

}  // namespace iso
