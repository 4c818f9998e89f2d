// Image files through OpenImageIO (image.h).
#include "viewer/image.h"

#include <OpenImageIO/imageio.h>

#include <glm/glm.hpp>
#include <glm/packing.hpp>

#include "iso/atomic_file.h"
#include "iso/error.h"
#include "pipeline/io/image.h"

namespace iso::viewer {
namespace OIIO = OIIO_NAMESPACE;

void writeImage(const std::filesystem::path& path, uint32_t width, uint32_t height,
                const std::vector<uint32_t>& rgba) {
  AtomicFile file(path);
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out)
    throw FileError(path.string(), std::nullopt,
                    "cannot write this kind of image (" + OIIO::geterror() + ")");
  const OIIO::ImageSpec spec(int(width), int(height), 4, OIIO::TypeDesc::UINT8);
  if (!out->open(file.temporaryPath().string(), spec) ||
      !out->write_image(OIIO::TypeDesc::UINT8, rgba.data()) || !out->close())
    throw FileError(path.string(), std::nullopt, "cannot write the image: " + out->geterror());
  file.commit();
}

std::vector<uint32_t> readImage(const std::filesystem::path& path, uint32_t& width,
                                uint32_t& height) {
  auto in = OIIO::ImageInput::open(path.string());
  if (!in)
    throw FileError(path.string(), std::nullopt, "cannot read the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  width = uint32_t(spec.width);
  height = uint32_t(spec.height);
  std::vector<uint8_t> pixels(size_t(width) * height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, pixels.data()))
    throw FileError(path.string(), std::nullopt, "cannot read the image: " + in->geterror());
  std::vector<uint32_t> out(size_t(width) * height);
  const int n = spec.nchannels;
  for (size_t i = 0; i < out.size(); ++i) {
    const uint8_t* p = &pixels[i * n];
    const uint32_t r = p[0], g = n > 1 ? p[1] : r, b = n > 2 ? p[2] : r, a = n > 3 ? p[3] : 255;
    out[i] = r | g << 8 | b << 16 | a << 24;
  }
  return out;
}

Environment loadEnvironment(const std::filesystem::path& path, uint32_t maxWidth) {
  const LinearImage image = readLinearImage(path, maxWidth);
  if (image.width < 2)
    throw FileError(path.string(), std::nullopt, "the environment map is too small");
  Environment env;
  env.width = image.width;
  env.height = image.height;
  env.texels.resize(image.texels.size() * 2);
  for (size_t i = 0; i < image.texels.size(); ++i) {
    const glm::vec3& c = image.texels[i];
    env.texels[2 * i] = glm::packHalf2x16({c.r, c.g});
    env.texels[2 * i + 1] = glm::packHalf2x16({c.b, 0.0f});
  }
  return env;
}

}  // namespace iso::viewer
