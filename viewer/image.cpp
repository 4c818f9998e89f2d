// Image files through OpenImageIO (image.h).
#include "image.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <glm/glm.hpp>
#include <glm/packing.hpp>

#include "iso/atomic_file.h"
#include "iso/error.h"
#include "iso/quantize.h"

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
  OIIO::ImageBuf source(path.string());
  if (!source.read(0, 0, true, OIIO::TypeDesc::FLOAT))
    throw FileError(path.string(), std::nullopt,
                    "cannot read the environment map: " + source.geterror());
  OIIO::ImageSpec spec = source.spec();
  if (spec.width < 2 || spec.height < 1)
    throw FileError(path.string(), std::nullopt, "the environment map is empty");
  // 8-bit images are sRGB-encoded; float images (EXR, HDR) are linear already.
  const bool encoded = spec.format.basetype == OIIO::TypeDesc::UINT8 ||
                       spec.format.basetype == OIIO::TypeDesc::UINT16;
  OIIO::ImageBuf image = source;
  if (uint32_t(spec.width) > maxWidth) {
    const int w = int(maxWidth), h = std::max(1, int(int64_t(spec.height) * w / spec.width));
    image = OIIO::ImageBufAlgo::resize(source, "box", 0.0f,
                                       OIIO::ROI(0, w, 0, h, 0, 1, 0, spec.nchannels));
    if (image.has_error())
      throw FileError(path.string(), std::nullopt, "cannot resize the environment map");
  }
  Environment env;
  env.width = uint32_t(image.spec().width);
  env.height = uint32_t(image.spec().height);
  const int n = image.spec().nchannels;
  std::vector<float> pixels(size_t(env.width) * env.height * n);
  image.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, pixels.data());
  const auto linear = [&](float c) { return encoded ? srgbToLinear(c) : std::max(c, 0.0f); };
  env.texels.resize(size_t(env.width) * env.height * 2);
  for (size_t i = 0; i < size_t(env.width) * env.height; ++i) {
    const float* p = &pixels[i * n];
    const float r = linear(p[0]), g = linear(n > 1 ? p[1] : p[0]), b = linear(n > 2 ? p[2] : p[0]);
    env.texels[2 * i] = glm::packHalf2x16({r, g});
    env.texels[2 * i + 1] = glm::packHalf2x16({b, 0.0f});
  }
  return env;
}

}  // namespace iso::viewer
