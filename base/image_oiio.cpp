// Images through OpenImageIO (image.h): the builds with ISO_WITH_OPENIMAGEIO.
#include "base/image.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>

#include "iso/atomic_file.h"
#include "iso/error.h"
#include "iso/quantize.h"

namespace iso {
namespace OIIO = OIIO_NAMESPACE;
namespace {
// OpenImageIO's message, or what it means when it gives none.
std::string reason(const std::string& error) {
  return error.empty() ? "not an image OpenImageIO reads, or a damaged one" : error;
}
}  // namespace

void checkImageReadable(const std::filesystem::path& path) {
  if (!std::filesystem::is_regular_file(path))
    throw FileError(path.string(), std::nullopt, "no such image file");
  auto in = OIIO::ImageInput::open(path.string());
  if (!in)
    throw FileError(path.string(), std::nullopt,
                    "cannot read the image: " + reason(OIIO::geterror()));
  if (in->spec().width < 1 || in->spec().height < 1)
    throw FileError(path.string(), std::nullopt, "the image is empty");
}

LinearImage readLinearImage(const std::filesystem::path& path, uint32_t maxWidth) {
  const auto fail = [&](const std::string& why) {
    throw FileError(path.string(), std::nullopt, why);
  };
  if (!std::filesystem::is_regular_file(path)) fail("no such image file");
  OIIO::ImageBuf source(path.string());
  if (!source.read(0, 0, true, OIIO::TypeDesc::FLOAT))
    fail("cannot read the image: " + reason(source.geterror()));
  const OIIO::ImageSpec& spec = source.spec();
  if (spec.width < 1 || spec.height < 1 || spec.nchannels < 1) fail("the image is empty");
  // 8- and 16-bit images are sRGB-encoded; float images (EXR, HDR) are linear already. (The
  // buffer holds floats now: the file's own format is the native spec's.)
  const OIIO::TypeDesc stored = source.nativespec().format;
  const bool encoded =
      stored.basetype == OIIO::TypeDesc::UINT8 || stored.basetype == OIIO::TypeDesc::UINT16;
  OIIO::ImageBuf image = source;
  if (maxWidth > 0 && uint32_t(spec.width) > maxWidth) {
    const int w = int(maxWidth), h = std::max(1, int(int64_t(spec.height) * w / spec.width));
    image = OIIO::ImageBufAlgo::resize(source, "box", 0.0f,
                                       OIIO::ROI(0, w, 0, h, 0, 1, 0, spec.nchannels));
    if (image.has_error()) fail("cannot resize the image: " + image.geterror());
  }
  LinearImage out;
  out.width = uint32_t(image.spec().width);
  out.height = uint32_t(image.spec().height);
  const int n = image.spec().nchannels;
  std::vector<float> pixels(size_t(out.width) * out.height * n);
  if (!image.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, pixels.data()))
    fail("cannot read the image's pixels: " + image.geterror());
  const auto linear = [&](float c) {
    return encoded ? srgbToLinear(std::clamp(c, 0.0f, 1.0f)) : std::max(c, 0.0f);
  };
  out.texels.resize(size_t(out.width) * out.height);
  for (size_t i = 0; i < out.texels.size(); ++i) {
    const float* p = &pixels[i * n];
    const bool gray = n < 3;
    out.texels[i] = {linear(p[0]), linear(gray ? p[0] : p[1]), linear(gray ? p[0] : p[2])};
  }
  return out;
}

void checkImageWritable(const std::filesystem::path& path, const std::string& option) {
  if (!OIIO::ImageOutput::create(path.string()))
    throw UsageError(option + ": cannot write this kind of image (" + path.string() + ": " +
                     OIIO::geterror() + ")");
}

void writeRgba8Image(const std::filesystem::path& path, uint32_t width, uint32_t height,
                     const std::vector<uint32_t>& rgba) {
  AtomicFile file(path);
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out)
    throw FileError(path.string(), std::nullopt,
                    "cannot write this kind of image (" + OIIO::geterror() + ")");
  // RGB alone where the format has no alpha (PPM, JPEG): each pixel's fourth byte skipped.
  const int channels = out->supports("alpha") ? 4 : 3;
  const OIIO::ImageSpec spec(int(width), int(height), channels, OIIO::TypeDesc::UINT8);
  if (!out->open(file.temporaryPath().string(), spec) ||
      !out->write_image(OIIO::TypeDesc::UINT8, rgba.data(), sizeof(uint32_t)) || !out->close())
    throw FileError(path.string(), std::nullopt, "cannot write the image: " + out->geterror());
  file.commit();
}

std::vector<uint32_t> readRgba8Image(const std::filesystem::path& path, uint32_t& width,
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

}  // namespace iso
