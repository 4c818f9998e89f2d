// PNG and PPM/PGM files without OpenImageIO (base/raster.h), held to what the image
// functions of this build read and write (base/image.h: OpenImageIO where the build has it),
// and the image functions of builds without OpenImageIO.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "iso/error.h"
#include "iso/quantize.h"
#include "base/image.h"
#include "base/raster.h"
#include "tests/support/support.h"

namespace iso::test {
namespace {

using namespace std::string_literals;  // "\x00" inside strings

std::vector<uint32_t> randomRgba(uint32_t width, uint32_t height, uint32_t seed) {
  std::mt19937 random(seed);
  std::vector<uint32_t> pixels(size_t(width) * height);
  for (uint32_t& p : pixels) p = uint32_t(random());
  return pixels;
}

std::vector<std::byte> bytesOf(const std::string& text) {
  const auto* p = reinterpret_cast<const std::byte*>(text.data());
  return {p, p + text.size()};
}

std::vector<uint32_t> withoutAlpha(std::vector<uint32_t> pixels) {
  for (uint32_t& p : pixels) p |= 0xFF000000u;
  return pixels;
}

// RGBA8 words of 8-bit RGB or RGBA samples.
std::vector<uint32_t> rgbaOf(const Raster& raster) {
  EXPECT_EQ(raster.maxValue, 255u);
  std::vector<uint32_t> out(size_t(raster.width) * raster.height);
  for (size_t i = 0; i < out.size(); ++i) {
    const uint16_t* s = &raster.samples[i * raster.channels];
    out[i] = s[0] | s[1] << 8 | s[2] << 16 | (raster.channels == 4 ? s[3] : 255u) << 24;
  }
  return out;
}

TEST(Raster, pngFilesKeepEveryPixelAndItsAlpha) {
  const std::vector<uint32_t> pixels = randomRgba(37, 23, 1);
  const std::vector<std::byte> png = encodePng(37, 23, pixels);
  EXPECT_TRUE(looksLikePng(png));
  EXPECT_FALSE(looksLikeNetpbm(png));
  const Raster raster = decodePng(png, "a.png");
  ASSERT_EQ(raster.width, 37u);
  ASSERT_EQ(raster.height, 23u);
  ASSERT_EQ(raster.channels, 4u);
  EXPECT_EQ(rgbaOf(raster), pixels);
}

TEST(Raster, ppmFilesKeepRgbAndDropAlpha) {
  const std::vector<uint32_t> pixels = randomRgba(5, 3, 2);
  const std::vector<std::byte> ppm = encodePpm(5, 3, pixels);
  EXPECT_TRUE(looksLikeNetpbm(ppm));
  EXPECT_FALSE(looksLikePng(ppm));
  const Raster raster = decodeNetpbm(ppm, "a.ppm");
  ASSERT_EQ(raster.channels, 3u);
  EXPECT_EQ(rgbaOf(raster), withoutAlpha(pixels));
}

// In builds with OpenImageIO: OpenImageIO reads the files these encoders write, and these decoders
// read the files OpenImageIO writes, pixel for pixel. (Opaque pixels: OpenImageIO premultiplies
// the colors of PNG files by their alpha when it reads them.)
TEST(Raster, theImageFunctionsReadWhatTheEncodersWrite) {
  TempDir dir;
  const std::vector<uint32_t> pixels = withoutAlpha(randomRgba(19, 11, 3));
  writeFile(dir / "a.png", encodePng(19, 11, pixels));
  writeFile(dir / "a.ppm", encodePpm(19, 11, pixels));
  uint32_t w = 0, h = 0;
  EXPECT_EQ(readRgba8Image(dir / "a.png", w, h), pixels);
  EXPECT_EQ(w, 19u);
  EXPECT_EQ(h, 11u);
  EXPECT_EQ(readRgba8Image(dir / "a.ppm", w, h), withoutAlpha(pixels));
}

TEST(Raster, theDecodersReadWhatTheImageFunctionsWrite) {
  TempDir dir;
  const std::vector<uint32_t> pixels = withoutAlpha(randomRgba(13, 17, 4));
  writeRgba8Image(dir / "a.png", 13, 17, pixels);
  writeRgba8Image(dir / "a.ppm", 13, 17, pixels);
  EXPECT_EQ(rgbaOf(decodePng(readFile(dir / "a.png"), "a.png")), pixels);
  EXPECT_EQ(rgbaOf(decodeNetpbm(readFile(dir / "a.ppm"), "a.ppm")), withoutAlpha(pixels));
}

TEST(Raster, netpbmHeadersTakeCommentsAndSamplesOfTwoBytes) {
  // A 3 × 2 gray image of maximum value 1000: 2 big-endian bytes a sample.
  std::string pgm = "P5\n# made by hand\n3 2 # size\n1000\n";
  for (uint16_t v : {0, 1, 255, 256, 999, 1000}) pgm += {char(v >> 8), char(v & 0xFF)};
  const Raster gray = decodeNetpbm(bytesOf(pgm), "g.pgm");
  EXPECT_EQ(gray.channels, 1u);
  EXPECT_EQ(gray.maxValue, 1000u);
  EXPECT_EQ(gray.samples, (std::vector<uint16_t>{0, 1, 255, 256, 999, 1000}));
  // Maximum value 7, one byte a sample; bytes after the image are not part of it.
  const Raster rgb = decodeNetpbm(bytesOf("P6 1 1 7\t\x07\x03\x00more"s), "c.ppm");
  EXPECT_EQ(rgb.samples, (std::vector<uint16_t>{7, 3, 0}));
}

TEST(Raster, malformedNetpbmFilesNameTheFileAndTheProblem) {
  const std::pair<std::string, std::string> cases[] = {
      {"P3\n1 1\n255\n0 0 0\n", "not a binary PGM (P5) or PPM (P6) file"},
      {"P6\n1\n", "the header has no height"},
      {"P6\n0 4\n255\n", "the image is empty"},
      {"P6\n1 1\n0\n...", "the maximum value must be 1 to 65535"},
      {"P6\n1 1\n65536\n......", "the maximum value must be 1 to 65535"},
      {"P6\n1 1\n255", "no white space after the header"},
      {"P6\n1 99999999999\n255\n", "the height is too large"},
      {"P6\n4294967295 4294967295\n255\n...", "the file ends inside the pixels"},
      {"P5\n2 1\n100\n\x64\x65", "a sample is above the maximum value 100"}};
  for (const auto& [text, reason] : cases) {
    try {
      decodeNetpbm(bytesOf(text), "bad.ppm");
      ADD_FAILURE() << text << " was read";
    } catch (const FileError& error) {
      EXPECT_EQ(error.file(), "bad.ppm");
      EXPECT_NE(error.reason().find(reason), std::string::npos) << error.what();
    }
  }
}

// Every prefix that cuts the pixels short. (A PNG file ends with an empty IEND chunk, 12 bytes
// after the pixels and their checksums, which libpng does not wait for.)
TEST(Raster, everyTruncatedPrefixOfAnImageIsRejected) {
  const std::vector<uint32_t> pixels = randomRgba(6, 5, 5);
  const std::vector<std::byte> png = encodePng(6, 5, pixels), ppm = encodePpm(6, 5, pixels);
  ASSERT_EQ(std::string(reinterpret_cast<const char*>(&png[png.size() - 8]), 4), "IEND");
  for (size_t n = 0; n < png.size() - 12; ++n)
    EXPECT_THROW(decodePng(std::span(png).first(n), "cut.png"), FileError) << n << " bytes";
  for (size_t n = 0; n < ppm.size(); ++n)
    EXPECT_THROW(decodeNetpbm(std::span(ppm).first(n), "cut.ppm"), FileError) << n << " bytes";
}

TEST(Image, picturesOfAKindTheBuildCannotWriteAreRefusedBeforeAnyWork) {
  EXPECT_NO_THROW(checkImageWritable("x.png", "--out"));
  EXPECT_NO_THROW(checkImageWritable("x.PPM", "--out"));
  EXPECT_THROW(checkImageWritable("x.not-an-image-format", "--out"), UsageError);
  EXPECT_THROW(checkImageWritable("no-extension", "--out"), UsageError);
}

#if !ISO_WITH_OPENIMAGEIO
TEST(ImageWithoutOpenImageIO, otherKindsOfImagesSayThisBuildHasNoOpenImageIO) {
  TempDir dir;
  try {
    checkImageWritable(dir / "x.exr", "--out");
    ADD_FAILURE() << "x.exr would be written";
  } catch (const UsageError& error) {
    EXPECT_NE(std::string(error.what()).find("--out"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("no OpenImageIO"), std::string::npos) << error.what();
  }
  EXPECT_THROW(writeRgba8Image(dir / "x.jpg", 1, 1, {0}), FileError);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.jpg"));
  writeFile(dir / "sky.hdr", bytesOf("#?RADIANCE\n"));
  try {
    readLinearImage(dir / "sky.hdr");
    ADD_FAILURE() << "sky.hdr was read";
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), (dir / "sky.hdr").string());
    EXPECT_NE(error.reason().find("no OpenImageIO"), std::string::npos) << error.what();
  }
}

TEST(ImageWithoutOpenImageIO, widerImagesAreBoxFilteredInLinearLight) {
  // 4 × 2 gray texels: two 2 × 2 blocks of codes 0 and 255, and 100 and 200.
  TempDir dir;
  writeFile(dir / "g.pgm", bytesOf("P5 4 2 255 \x00\xFF\x64\xC8\xFF\x00\xC8\x64"s));
  const LinearImage image = readLinearImage(dir / "g.pgm", 2);
  ASSERT_EQ(image.width, 2u);
  ASSERT_EQ(image.height, 1u);
  EXPECT_NEAR(image.texels[0].r, 0.5f, 1e-6f);
  EXPECT_NEAR(image.texels[1].g, 0.5f * (srgb8ToLinear(100) + srgb8ToLinear(200)), 1e-6f);
}
#endif

}  // namespace
}  // namespace iso::test
