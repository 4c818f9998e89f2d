// The LAS reader on files built byte by byte from the ASPRS LAS 1.4 specification (R15): versions
// 1.2–1.4, point formats 0–10, scale and offset, 8- and 16-bit colors, extra bytes, VLRs, LAZ
// refusal, truncation and hostile headers.
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>

#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using test::Bytes;

// Standard record size of each point format and where its RGB starts (0: no RGB), from the spec's
// record tables (sections 2.6–2.16), written here independently of the reader.
constexpr uint16_t kStandardSize[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
constexpr uint16_t kRgbOffset[11] = {0, 0, 20, 28, 0, 28, 0, 30, 30, 0, 30};

// Public header offsets used to make headers hostile.
constexpr size_t kVersionMajorAt = 24;
constexpr size_t kHeaderSizeAt = 94;
constexpr size_t kPointDataOffsetAt = 96;
constexpr size_t kPointFormatAt = 104;
constexpr size_t kRecordLengthAt = 105;
constexpr size_t kLegacyCountAt = 107;
constexpr size_t kScaleAt = 131;
constexpr size_t kCount64At = 247;

struct LasPoint {
  int32_t x = 0, y = 0, z = 0;
  uint16_t red = 0, green = 0, blue = 0;
};

struct LasSpec {
  int minor = 2;
  int format = 0;
  int extraBytes = 0;
  glm::dvec3 scale{0.01};
  glm::dvec3 offset{0.0};
  std::vector<LasPoint> points{};
  int vlrPayload = -1;  // bytes of one VLR's payload; negative: no VLR
};

size_t headerSizeOf(int minor) { return minor >= 4 ? 375 : minor == 3 ? 235 : 227; }

Bytes makeLas(const LasSpec& s) {
  const size_t headerSize = headerSizeOf(s.minor);
  const size_t recordLength = kStandardSize[s.format] + size_t(s.extraBytes);
  const size_t vlrBytes = s.vlrPayload >= 0 ? 54 + size_t(s.vlrPayload) : 0;
  const uint64_t count = s.points.size();
  Bytes b;
  b.text("LASF").le<uint16_t>(7).le<uint16_t>(0).fill(16, 0).le<uint8_t>(1).le(uint8_t(s.minor));
  b.text("iso test").fill(24, 0).text("las_reader_test").fill(17, 0);
  b.le<uint16_t>(1).le<uint16_t>(2024).le(uint16_t(headerSize)).le(uint32_t(headerSize + vlrBytes));
  b.le(uint32_t(s.vlrPayload >= 0 ? 1 : 0)).le(uint8_t(s.format)).le(uint16_t(recordLength));
  b.le(uint32_t(s.format < 6 ? count : 0)).fill(20, 0);
  for (int axis = 0; axis < 3; ++axis) b.le(s.scale[axis]);
  for (int axis = 0; axis < 3; ++axis) b.le(s.offset[axis]);
  b.fill(48, 0);  // bounds
  if (s.minor >= 3) b.le<uint64_t>(0);
  if (s.minor >= 4) b.le<uint64_t>(0).le<uint32_t>(0).le(count).fill(15 * 8, 0);
  EXPECT_EQ(b.size(), headerSize);
  if (s.vlrPayload >= 0) {
    b.le<uint16_t>(0).text("LASF_Projection").fill(1, 0).le<uint16_t>(34735);
    b.le(uint16_t(s.vlrPayload)).fill(32, 0).fill(size_t(s.vlrPayload), 0x55);
  }
  for (const LasPoint& p : s.points) {
    b.le(p.x).le(p.y).le(p.z);
    const size_t rgb = kRgbOffset[s.format];
    if (rgb != 0) b.fill(rgb - 12, 0xA5).le(p.red).le(p.green).le(p.blue);
    b.fill(kStandardSize[s.format] - (rgb != 0 ? rgb + 6 : 12), 0xA5);
    b.fill(size_t(s.extraBytes), 0xEE);
  }
  return b;
}

std::vector<LasPoint> samplePoints() {
  return {{123456, -7, 2, 1000, 30000, 65535},
          {std::numeric_limits<int32_t>::max(), std::numeric_limits<int32_t>::min(), 0, 0, 256, 1},
          {-1, 0, 1, 65535, 0, 4096}};
}

glm::dvec3 expectedPosition(const LasSpec& s, const LasPoint& p) {
  return {double(p.x) * s.scale.x + s.offset.x, double(p.y) * s.scale.y + s.offset.y,
          double(p.z) * s.scale.z + s.offset.z};
}

float linearOf16(uint16_t code) {
  const float c = float(code) / 65535.0f;
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

std::string lasError(const Bytes& file, const std::string& name = "h.las") {
  test::TempDir dir;
  test::writeFile(dir / name, file.bytes());
  return test::readError(dir / name);
}

TEST(LasReader, positionsAreIntegerTimesScalePlusOffsetInDouble) {
  LasSpec spec{.scale = {0.001, 0.01, 0.25}, .offset = {515000.0, 4918000.0, -10.0}};
  spec.points = samplePoints();
  test::TempDir dir;
  test::writeFile(dir / "p.las", makeLas(spec).bytes());
  const auto reader = openPointFile(dir / "p.las");
  EXPECT_EQ(reader->info().format, "las 1.2 format 0");
  EXPECT_EQ(reader->info().declaredPoints, 3u);
  EXPECT_FALSE(reader->info().hasColors);
  const PointCloud points = readPointFile(dir / "p.las");
  ASSERT_EQ(points.size(), 3u);
  for (size_t i = 0; i < 3; ++i)
    EXPECT_EQ(points.positions[i], expectedPosition(spec, spec.points[i])) << i;
  EXPECT_EQ(points.positions[0], glm::dvec3(515123.456, 4917999.93, -9.5));
}

TEST(LasReader, isRecognizedByItsSignatureWhateverTheExtension) {
  LasSpec spec;
  spec.points = samplePoints();
  test::TempDir dir;
  test::writeFile(dir / "scan.dat", makeLas(spec).bytes());
  EXPECT_EQ(openPointFile(dir / "scan.dat")->info().format, "las 1.2 format 0");
}

TEST(LasReader, readsEveryPointFormatWithItsColors) {
  test::TempDir dir;
  for (int format = 0; format <= 10; ++format) {
    SCOPED_TRACE("format " + std::to_string(format));
    LasSpec spec{.minor = format >= 6 ? 4 : 2, .format = format, .offset = {100, 200, 300}};
    spec.points = samplePoints();
    test::writeFile(dir / "f.las", makeLas(spec).bytes());
    const auto reader = openPointFile(dir / "f.las");
    const bool hasColors = kRgbOffset[format] != 0;
    EXPECT_EQ(reader->info().hasColors, hasColors);
    EXPECT_EQ(reader->info().format,
              "las 1." + std::to_string(spec.minor) + " format " + std::to_string(format));
    const PointCloud points = readPointFile(dir / "f.las");
    ASSERT_EQ(points.size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(points.positions[i], expectedPosition(spec, spec.points[i]));
      if (!hasColors) continue;
      // Channels above 255 in the first points: 16-bit colors.
      EXPECT_FLOAT_EQ(points.colors[i].r, linearOf16(spec.points[i].red));
      EXPECT_FLOAT_EQ(points.colors[i].g, linearOf16(spec.points[i].green));
      EXPECT_FLOAT_EQ(points.colors[i].b, linearOf16(spec.points[i].blue));
    }
  }
}

TEST(LasReader, readsEightBitValuesInSixteenBitColorFieldsAsEightBit) {
  LasSpec spec{.format = 2};
  spec.points = {{0, 0, 0, 255, 0, 128}, {1, 1, 1, 10, 20, 30}};
  test::TempDir dir;
  test::writeFile(dir / "c.las", makeLas(spec).bytes());
  const PointCloud points = readPointFile(dir / "c.las");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_FLOAT_EQ(points.colors[0].r, 1.0f);
  EXPECT_NEAR(points.colors[0].b, test::linearOf8(128), 1e-6);
  EXPECT_NEAR(points.colors[1].g, test::linearOf8(20), 1e-6);

  spec.points.push_back({2, 2, 2, 256, 0, 0});  // one larger value: the file is 16-bit
  test::writeFile(dir / "c.las", makeLas(spec).bytes());
  const PointCloud sixteen = readPointFile(dir / "c.las");
  EXPECT_FLOAT_EQ(sixteen.colors[0].r, linearOf16(255));
}

TEST(LasReader, skipsExtraBytesAndVariableLengthRecords) {
  LasSpec spec{.minor = 3, .format = 3, .extraBytes = 7, .scale = {0.5, 0.25, 0.125}};
  spec.vlrPayload = 100;
  spec.points = samplePoints();
  test::TempDir dir;
  test::writeFile(dir / "x.las", makeLas(spec).bytes());
  const PointCloud points = test::readInBatches(dir / "x.las", {}, nullptr, 2);
  ASSERT_EQ(points.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(points.positions[i], expectedPosition(spec, spec.points[i]));
    EXPECT_FLOAT_EQ(points.colors[i].b, linearOf16(spec.points[i].blue));
  }
}

TEST(LasReader, usesTheSixtyFourBitCountOfLas14) {
  LasSpec spec{.minor = 4, .format = 6};
  spec.points = samplePoints();
  Bytes file = makeLas(spec);
  EXPECT_EQ(std::to_integer<int>(file.bytes()[kLegacyCountAt]), 0);  // legacy count unused
  test::TempDir dir;
  test::writeFile(dir / "l.las", file.bytes());
  EXPECT_EQ(openPointFile(dir / "l.las")->info().declaredPoints, 3u);
  EXPECT_EQ(readPointFile(dir / "l.las").size(), 3u);
}

TEST(LasReader, refusesLazByPointFormatBitsAndByExtension) {
  const std::string message =
      "LAZ (compressed LAS) is not supported: decompress it first (for example with laszip or pdal "
      "translate)";
  LasSpec spec{.format = 3};
  spec.points = samplePoints();
  for (uint8_t bit : {uint8_t{0x80}, uint8_t{0x40}}) {
    Bytes file = makeLas(spec);
    file.patchLE<uint8_t>(kPointFormatAt, uint8_t(3 | bit));
    EXPECT_NE(lasError(file).find(message), std::string::npos);
  }
  EXPECT_NE(lasError(makeLas(spec), "a.laz").find(message), std::string::npos);
  EXPECT_NE(lasError(Bytes().text("not las at all"), "b.laz").find(message), std::string::npos);
}

TEST(LasReader, everyTruncatedPrefixThrowsFileError) {
  LasSpec spec{.minor = 4, .format = 7, .extraBytes = 3};
  spec.vlrPayload = 10;
  spec.points = samplePoints();
  const std::vector<std::byte> whole = makeLas(spec).bytes();
  test::TempDir dir;
  test::writeFile(dir / "whole.las", whole);
  ASSERT_EQ(readPointFile(dir / "whole.las").size(), 3u);
  for (size_t length = 0; length < whole.size(); ++length) {
    SCOPED_TRACE("prefix of " + std::to_string(length) + " bytes");
    test::writeFile(dir / "cut.las", {whole.begin(), whole.begin() + ptrdiff_t(length)});
    EXPECT_THROW(readPointFile(dir / "cut.las"), FileError);
  }
}

TEST(LasReader, truncatedPointDataNamesTheOffsetAndCount) {
  LasSpec spec{.format = 1};
  spec.points = samplePoints();
  const Bytes whole = makeLas(spec);
  const std::vector<std::byte> cut(whole.bytes().begin(), whole.bytes().end() - 5);
  test::TempDir dir;
  test::writeFile(dir / "t.las", cut);
  test::writeGzip(dir / "t.las.gz", cut);
  for (const char* name : {"t.las", "t.las.gz"}) {
    SCOPED_TRACE(name);
    try {
      readPointFile(dir / name);
      FAIL() << "no error";
    } catch (const FileError& error) {
      EXPECT_EQ(error.reason(), "file ends after 2 of 3 points");
      EXPECT_EQ(error.offset(), 227u + 2 * 28);
    }
  }
}

TEST(LasReader, hostileHeadersAreClearErrorsWithoutHugeWork) {
  LasSpec spec{.minor = 4, .format = 0};
  spec.points = samplePoints();
  const Bytes valid = makeLas(spec);
  const auto patched = [&](auto change) {
    Bytes file = valid;
    change(file);
    return file;
  };
  const std::vector<std::pair<Bytes, std::string>> cases = {
      {patched([](Bytes& f) {
         f.patchLE<uint32_t>(kLegacyCountAt, 0xFFFFFFFFu);
         f.patchLE<uint64_t>(kCount64At, 0);  // LAS 1.4 falls back to the legacy count
       }),
       "file ends after 3 of 4294967295 points"},
      {patched([](Bytes& f) { f.patchLE<uint64_t>(kCount64At, uint64_t{1} << 62); }),
       "file ends after 3 of 4611686018427387904 points"},
      {patched([](Bytes& f) { f.patchLE<uint32_t>(kPointDataOffsetAt, 0xFFFFFFF0u); }),
       "past the end of the file"},
      {patched([](Bytes& f) { f.patchLE<uint32_t>(kPointDataOffsetAt, 100); }),
       "offset to point data 100 lies inside the 375-byte header"},
      {patched([](Bytes& f) { f.patchLE<uint16_t>(kRecordLengthAt, 12); }),
       "point record length 12 is smaller than the 20 bytes of point format 0"},
      {patched([](Bytes& f) { f.patchLE<uint16_t>(kHeaderSizeAt, 227); }),
       "header size 227 is smaller than the LAS 1.4 header (375 bytes)"},
      {patched([](Bytes& f) { f.patchLE<double>(kScaleAt + 8, 0.0); }), "non-zero"},
      {patched([](Bytes& f) { f.patchLE<uint8_t>(kVersionMajorAt, 2); }),
       "unsupported LAS version 2.4"},
      {patched([](Bytes& f) { f.patchLE<uint8_t>(kPointFormatAt, 11); }),
       "unsupported LAS point data format 11"},
      {Bytes().text("LASF").fill(100, 0), "file ends inside the LAS header (104 of 227 bytes)"},
  };
  for (const auto& [file, reason] : cases) {
    SCOPED_TRACE(reason);
    const auto start = std::chrono::steady_clock::now();
    const std::string error = lasError(file);
    EXPECT_NE(error.find(reason), std::string::npos) << error;
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  }
}

TEST(LasReader, hostileCountsInCompressedInputEndAsTruncation) {
  // A .gz file's size is unknown up front: the count is caught while streaming.
  LasSpec spec{.format = 2};
  spec.points = samplePoints();
  Bytes file = makeLas(spec);
  file.patchLE<uint32_t>(kLegacyCountAt, 0xFFFFFFFFu);
  test::TempDir dir;
  test::writeGzip(dir / "h.las.gz", file.bytes());
  EXPECT_NE(test::readError(dir / "h.las.gz").find("file ends after 3 of 4294967295 points"),
            std::string::npos);
  file.patchLE<uint32_t>(kPointDataOffsetAt, 0xFFFFFFF0u);
  test::writeGzip(dir / "o.las.gz", file.bytes());
  EXPECT_NE(
      test::readError(dir / "o.las.gz").find("file ends before the point data at byte 4294967280"),
      std::string::npos);
}

}  // namespace
}  // namespace iso
