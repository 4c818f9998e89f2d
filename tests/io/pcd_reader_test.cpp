// The PCD reader on files built from the PCD v0.7 format description (PCL documentation, "The PCD
// (Point Cloud Data) file format"): ascii, binary and binary_compressed data, every scalar type,
// packed and separate colors, normals, organized clouds with NaN points, fields in any order, and
// errors for malformed headers, data and compressed blocks.
#include <lzf.h>

#include <array>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/io/color.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using test::Bytes;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A PCD header as PCL writes it: comment, VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT,
// VIEWPOINT, POINTS and DATA on lines 1 to 11, so that the data starts on line 12. POINTS is
// WIDTH x HEIGHT unless given.
struct Header {
  std::string fields = "x y z";
  std::string size = "4 4 4";
  std::string type = "F F F";
  std::string count = "1 1 1";
  uint64_t width = 0;
  uint64_t height = 1;
  std::string data = "ascii";
  std::optional<uint64_t> points = std::nullopt;

  std::string text() const {
    return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " +
           size + "\nTYPE " + type + "\nCOUNT " + count + "\nWIDTH " + std::to_string(width) +
           "\nHEIGHT " + std::to_string(height) + "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
           std::to_string(points.value_or(width * height)) + "\nDATA " + data + "\n";
  }
};

Bytes& append(Bytes& to, const Bytes& from) {
  for (std::byte b : from.bytes()) to.le(b);
  return to;
}

Bytes pcdFile(const Header& header, const Bytes& data) {
  Bytes file;
  file.text(header.text());
  return append(file, data);
}

// PCL's binary_compressed data: the compressed size, the uncompressed size (uint32 each), then the
// LZF-compressed block of all fields one after the other.
Bytes compressedBlock(const Bytes& fieldByField) {
  const std::vector<std::byte>& raw = fieldByField.bytes();
  std::vector<std::byte> packed(raw.size() * 2 + 64);
  const unsigned size =
      lzf_compress(raw.data(), unsigned(raw.size()), packed.data(), unsigned(packed.size()));
  EXPECT_GT(size, 0u);
  Bytes block;
  block.le<uint32_t>(size).le(uint32_t(raw.size()));
  for (size_t i = 0; i < size; ++i) block.le(packed[i]);
  return block;
}

// Positions, some of which float cannot hold exactly (0.1, -7.3), so that rounding shows.
const std::vector<glm::dvec3> kPositions = {
    {1.5, -2.25, 3.0}, {0.1, 1e5, -7.3}, {-1000.125, 0.0, 4.2e6}};

Bytes floatRecords(const std::vector<glm::dvec3>& positions) {
  Bytes data;
  for (const glm::dvec3& p : positions) data.le(float(p.x)).le(float(p.y)).le(float(p.z));
  return data;
}

Bytes floatColumns(const std::vector<glm::dvec3>& positions) {
  Bytes data;
  for (int axis = 0; axis < 3; ++axis)
    for (const glm::dvec3& p : positions) data.le(float(p[axis]));
  return data;
}

// The shortest decimal text of a double that reads back as the same value (also for NaN).
std::string decimal(double value) {
  char text[64];
  const auto result = std::to_chars(text, text + sizeof(text), value);
  return std::string(text, result.ptr);
}

std::string asciiLines(const std::vector<glm::dvec3>& positions) {
  std::string lines;
  for (const glm::dvec3& p : positions)
    lines += decimal(p.x) + " " + decimal(p.y) + " " + decimal(p.z) + "\n";
  return lines;
}

void expectPositions(const PointCloud& points, const std::vector<glm::dvec3>& expected) {
  ASSERT_EQ(points.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) EXPECT_EQ(points.positions[i], expected[i]) << i;
}

std::vector<glm::dvec3> roundedToFloat(const std::vector<glm::dvec3>& positions) {
  std::vector<glm::dvec3> rounded;
  for (const glm::dvec3& p : positions) rounded.push_back(test::roundedToFloat(p));
  return rounded;
}

void expectColor(const glm::vec3& color, int red, int green, int blue) {
  EXPECT_NEAR(color.r, test::linearOf8(red), 1e-6);
  EXPECT_NEAR(color.g, test::linearOf8(green), 1e-6);
  EXPECT_NEAR(color.b, test::linearOf8(blue), 1e-6);
}

std::string pcdError(const Bytes& file) {
  test::TempDir dir;
  test::writeFile(dir / "h.pcd", file.bytes());
  return test::readError(dir / "h.pcd");
}

std::string pcdError(const std::string& text) { return pcdError(Bytes().text(text)); }

TEST(PcdReader, readsAsciiPointsRoundingFloatFieldsToFloat) {
  test::TempDir dir;
  const Header header{.width = 3};
  test::writeText(dir / "a.pcd", header.text() + asciiLines(kPositions));
  const auto reader = openPointFile(dir / "a.pcd");
  EXPECT_EQ(reader->info().format, "pcd-ascii");
  EXPECT_EQ(reader->info().declaredPoints, 3u);
  EXPECT_FALSE(reader->info().hasNormals);
  EXPECT_FALSE(reader->info().hasColors);
  expectPositions(readPointFile(dir / "a.pcd"), roundedToFloat(kPositions));

  // F8 fields keep double precision; blank lines and "\r\n" line ends are allowed.
  const Header doubles{.size = "8 8 8", .width = 3};
  std::string lines = asciiLines(kPositions);
  lines.replace(lines.find('\n'), 1, "\r\n\n  \n");
  test::writeText(dir / "d.pcd", doubles.text() + lines);
  expectPositions(readPointFile(dir / "d.pcd"), kPositions);
}

TEST(PcdReader, readsBinaryAndBinaryCompressedPositions) {
  test::TempDir dir;
  test::writeFile(dir / "b.pcd",
                  pcdFile({.width = 3, .data = "binary"}, floatRecords(kPositions)).bytes());
  test::writeFile(dir / "c.pcd", pcdFile({.width = 3, .data = "binary_compressed"},
                                         compressedBlock(floatColumns(kPositions)))
                                     .bytes());
  EXPECT_EQ(openPointFile(dir / "b.pcd")->info().format, "pcd-binary");
  EXPECT_EQ(openPointFile(dir / "c.pcd")->info().format, "pcd-binary-compressed");
  EXPECT_EQ(openPointFile(dir / "c.pcd")->info().declaredPoints, 3u);
  expectPositions(readPointFile(dir / "b.pcd"), roundedToFloat(kPositions));
  expectPositions(readPointFile(dir / "c.pcd"), roundedToFloat(kPositions));
}

// Write x of type T (y and z F4) in binary and binary_compressed, and read it back exactly.
template <typename T>
void expectBinaryX(const std::string& type, T first, T second) {
  SCOPED_TRACE(type + std::to_string(sizeof(T)));
  const Header header{
      .size = std::to_string(sizeof(T)) + " 4 4", .type = type + " F F", .width = 2};
  Bytes records;
  records.le(first).le(0.5f).le(-1.0f).le(second).le(2.0f).le(3.0f);
  Bytes columns;
  columns.le(first).le(second).le(0.5f).le(2.0f).le(-1.0f).le(3.0f);
  Header binary = header;
  binary.data = "binary";
  Header compressed = header;
  compressed.data = "binary_compressed";
  for (const Bytes& file :
       {pcdFile(binary, records), pcdFile(compressed, compressedBlock(columns))}) {
    test::TempDir dir;
    test::writeFile(dir / "t.pcd", file.bytes());
    expectPositions(readPointFile(dir / "t.pcd"),
                    {{double(first), 0.5, -1.0}, {double(second), 2.0, 3.0}});
  }
}

TEST(PcdReader, readsCoordinatesOfEveryScalarType) {
  expectBinaryX<int8_t>("I", -128, 127);
  expectBinaryX<int16_t>("I", -32768, 1234);
  expectBinaryX<int32_t>("I", std::numeric_limits<int32_t>::min(), 7);
  expectBinaryX<int64_t>("I", -(int64_t{1} << 40), int64_t{1} << 52);
  expectBinaryX<uint8_t>("U", 255, 3);
  expectBinaryX<uint16_t>("U", 65535, 9);
  expectBinaryX<uint32_t>("U", 4000000000u, 11);
  expectBinaryX<uint64_t>("U", uint64_t{1} << 53, 13);
  expectBinaryX<float>("F", 0.1f, -3e38f);
  expectBinaryX<double>("F", 0.1, 1e300);
}

TEST(PcdReader, dropsAndCountsTheNanPointsOfOrganizedClouds) {
  // A 3 x 2 organized cloud with invalid points 1 and 3; colors must stay with their points.
  const std::vector<glm::dvec3> grid = {kPositions[0],      {kNaN, kNaN, kNaN}, kPositions[1],
                                        {kNaN, kNaN, kNaN}, kPositions[2],      {7, 8, 9}};
  const std::vector<uint32_t> colors = {0x010203, 0xFFFFFF, 0x040506, 0xFFFFFF, 0x070809, 0x0A0B0C};
  Header header{.fields = "x y z rgb",
                .size = "4 4 4 4",
                .type = "F F F U",
                .count = "1 1 1 1",
                .width = 3,
                .height = 2};
  std::string lines;
  Bytes records;
  Bytes columns = floatColumns(grid);
  for (size_t i = 0; i < grid.size(); ++i) {
    lines += decimal(grid[i].x) + " " + decimal(grid[i].y) + " " + decimal(grid[i].z) + " " +
             std::to_string(colors[i]) + "\n";
    records.le(float(grid[i].x)).le(float(grid[i].y)).le(float(grid[i].z)).le(colors[i]);
    columns.le(colors[i]);
  }
  std::vector<Bytes> files;
  files.push_back(Bytes().text(header.text() + lines));
  header.data = "binary";
  files.push_back(pcdFile(header, records));
  header.data = "binary_compressed";
  files.push_back(pcdFile(header, compressedBlock(columns)));
  for (const Bytes& file : files) {
    test::TempDir dir;
    test::writeFile(dir / "o.pcd", file.bytes());
    SCOPED_TRACE(openPointFile(dir / "o.pcd")->info().format);
    EXPECT_EQ(openPointFile(dir / "o.pcd")->info().declaredPoints, 6u);
    ReadStats stats;
    const PointCloud points = test::readInBatches(dir / "o.pcd", {}, &stats, 2);
    expectPositions(points,
                    roundedToFloat({kPositions[0], kPositions[1], kPositions[2], {7, 8, 9}}));
    EXPECT_EQ(stats.pointsRead, 4u);
    EXPECT_EQ(stats.droppedNonFinite, 2u);
    if (points.size() != 4) continue;
    expectColor(points.colors[0], 1, 2, 3);
    expectColor(points.colors[1], 4, 5, 6);
    expectColor(points.colors[3], 10, 11, 12);
  }
}

TEST(PcdReader, decodesPackedRgbFromFloatBitsOrIntegersIgnoringAlpha) {
  test::TempDir dir;
  const float rgbFloat = std::bit_cast<float>(uint32_t{0x00FF8040});
  Bytes records = floatRecords({kPositions[0]});
  records.le(rgbFloat);
  test::writeFile(dir / "f.pcd", pcdFile({.fields = "x y z rgb",
                                          .size = "4 4 4 4",
                                          .type = "F F F F",
                                          .count = "1 1 1 1",
                                          .width = 1,
                                          .data = "binary"},
                                         records)
                                     .bytes());
  records = floatRecords({kPositions[0]});
  records.le(uint32_t{0x7F0A141E});
  test::writeFile(dir / "u.pcd", pcdFile({.fields = "x y z rgba",
                                          .size = "4 4 4 4",
                                          .type = "F F F U",
                                          .count = "1 1 1 1",
                                          .width = 1,
                                          .data = "binary"},
                                         records)
                                     .bytes());
  // Text: current PCL writes the bits as an integer, older versions the float itself.
  const Header ascii{
      .fields = "x y z rgb", .size = "4 4 4 4", .type = "F F F F", .count = "1 1 1 1", .width = 3};
  test::writeText(dir / "a.pcd", ascii.text() + "0 0 0 16744512\n0 0 0 " + decimal(rgbFloat) +
                                     "\n0 0 0 4278210592\n");
  const Header signedRgba{
      .fields = "x y z rgba", .size = "4 4 4 4", .type = "F F F I", .count = "1 1 1 1", .width = 1};
  test::writeText(dir / "i.pcd", signedRgba.text() + "0 0 0 -15720400\n");  // 0xFF102030

  EXPECT_TRUE(openPointFile(dir / "f.pcd")->info().hasColors);
  expectColor(readPointFile(dir / "f.pcd").colors.at(0), 255, 128, 64);
  expectColor(readPointFile(dir / "u.pcd").colors.at(0), 10, 20, 30);
  const PointCloud text = readPointFile(dir / "a.pcd");
  ASSERT_EQ(text.size(), 3u);
  expectColor(text.colors[0], 255, 128, 64);
  expectColor(text.colors[1], 255, 128, 64);
  expectColor(text.colors[2], 0x00, 0x50, 0x20);  // 0xFF005020
  expectColor(readPointFile(dir / "i.pcd").colors.at(0), 0x10, 0x20, 0x30);
}

// Packed colors as PCL writes them: rgb (PointXYZRGB) or rgba (PointXYZRGBA), TYPE F (the bits
// of a float) or U, SIZE 4, in every data kind. Text holds the bits as an integer (current PCL) or
// the float itself (older PCL; not for fully opaque colors, whose float is a NaN).
TEST(PcdReader, readsPackedRgbAndRgbaAsFloatOrUnsignedInEveryDataKind) {
  const std::vector<uint32_t> packed = {0xFF102030, 0x00FF8040, 0xFFFFFFFF, 0x7F0A141E, 0x00000001};
  std::vector<glm::dvec3> positions;
  for (size_t i = 0; i < packed.size(); ++i) positions.push_back({double(i), 2.0 * i, -0.5 * i});
  test::TempDir dir;
  for (const std::string data : {"ascii", "binary", "binary_compressed"})
    for (const std::string field : {"rgb", "rgba"})
      for (const std::string type : {"F", "U"}) {
        SCOPED_TRACE(data + " " + field + " " + type);
        const Header header{.fields = "x y z " + field,
                            .size = "4 4 4 4",
                            .type = "F F F " + type,
                            .count = "1 1 1 1",
                            .width = packed.size(),
                            .data = data};
        Bytes body;
        if (data == "ascii") {
          std::string lines;
          for (size_t i = 0; i < packed.size(); ++i) {
            const float asFloat = std::bit_cast<float>(packed[i]);
            const bool asFloatText = type == "F" && (packed[i] >> 24) != 0xFF && i % 2 == 1;
            lines += decimal(positions[i].x) + " " + decimal(positions[i].y) + " " +
                     decimal(positions[i].z) + " " +
                     (asFloatText ? decimal(asFloat) : std::to_string(packed[i])) + "\n";
          }
          body.text(lines);
        } else if (data == "binary") {
          for (size_t i = 0; i < packed.size(); ++i) {
            append(body, floatRecords({positions[i]}));
            body.le(packed[i]);
          }
        } else {
          Bytes columns = floatColumns(positions);
          for (uint32_t bits : packed) columns.le(bits);
          body = compressedBlock(columns);
        }
        test::writeFile(dir / "c.pcd", pcdFile(header, body).bytes());
        EXPECT_TRUE(openPointFile(dir / "c.pcd")->info().hasColors);
        const PointCloud points = test::readInBatches(dir / "c.pcd", {}, nullptr, 2);
        expectPositions(points, positions);
        for (size_t i = 0; i < packed.size(); ++i)
          expectColor(points.colors[i], int(packed[i] >> 16 & 0xFF), int(packed[i] >> 8 & 0xFF),
                      int(packed[i] & 0xFF));
      }
}

// A packed color written as the text of a NaN float has lost its bits: an error, not a made-up
// color.
TEST(PcdReader, aPackedColorWrittenAsNanIsAnError) {
  const Header header{
      .fields = "x y z rgba", .size = "4 4 4 4", .type = "F F F F", .count = "1 1 1 1", .width = 1};
  EXPECT_NE(pcdError(header.text() + "1 2 3 nan\n")
                .find("line 12: value 4 (field 'rgba') is not a color: 'nan'"),
            std::string::npos)
      << pcdError(header.text() + "1 2 3 nan\n");
}

TEST(PcdReader, decodesSeparateRgbFieldsAsBytesOrUnitFloats) {
  test::TempDir dir;
  const uint8_t codes[2][3] = {{255, 128, 0}, {1, 2, 3}};
  Bytes records;
  for (size_t i = 0; i < 2; ++i) {
    append(records, floatRecords({kPositions[i]}));
    for (uint8_t code : codes[i]) records.le(code);
  }
  test::writeFile(dir / "u.pcd", pcdFile({.fields = "x y z r g b",
                                          .size = "4 4 4 1 1 1",
                                          .type = "F F F U U U",
                                          .count = "1 1 1 1 1 1",
                                          .width = 2,
                                          .data = "binary"},
                                         records)
                                     .bytes());
  const PointCloud bytePoints = test::readInBatches(dir / "u.pcd");
  ASSERT_EQ(bytePoints.size(), 2u);
  expectColor(bytePoints.colors[0], 255, 128, 0);
  expectColor(bytePoints.colors[1], 1, 2, 3);

  const Header floats{.fields = "x y z red green blue",
                      .size = "4 4 4 4 4 4",
                      .type = "F F F F F F",
                      .count = "1 1 1 1 1 1",
                      .width = 1};
  test::writeText(dir / "f.pcd", floats.text() + "1 2 3 0.5 1 7\n");
  const PointCloud floatPoints = readPointFile(dir / "f.pcd");
  ASSERT_EQ(floatPoints.size(), 1u);
  EXPECT_NEAR(floatPoints.colors[0].r, srgbToLinear(0.5f), 1e-6);
  EXPECT_FLOAT_EQ(floatPoints.colors[0].g, 1.0f);
  EXPECT_FLOAT_EQ(floatPoints.colors[0].b, 1.0f);  // 7 on a 0–1 scale: clamped

  // Two of three channels are no color.
  const Header partial{.fields = "x y z r g",
                       .size = "4 4 4 1 1",
                       .type = "F F F U U",
                       .count = "1 1 1 1 1",
                       .width = 1};
  test::writeText(dir / "p.pcd", partial.text() + "1 2 3 4 5\n");
  EXPECT_FALSE(openPointFile(dir / "p.pcd")->info().hasColors);
  EXPECT_EQ(readPointFile(dir / "p.pcd").size(), 1u);
}

TEST(PcdReader, readsNormalsOnlyWhenAllThreeArePresent) {
  test::TempDir dir;
  Bytes records;
  records.le(1.0f).le(2.0f).le(3.0f).le(0.6).le(0.8).le(1e300);  // F8 normals, one out of range
  test::writeFile(dir / "n.pcd", pcdFile({.fields = "x y z normal_x normal_y normal_z",
                                          .size = "4 4 4 8 8 8",
                                          .type = "F F F F F F",
                                          .count = "1 1 1 1 1 1",
                                          .width = 1,
                                          .data = "binary"},
                                         records)
                                     .bytes());
  const auto reader = openPointFile(dir / "n.pcd");
  EXPECT_TRUE(reader->info().hasNormals);
  const PointCloud points = readPointFile(dir / "n.pcd");
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points.normals[0], glm::vec3(0.6f, 0.8f, std::numeric_limits<float>::infinity()));

  const Header two{.fields = "x y z normal_x normal_y",
                   .size = "4 4 4 4 4",
                   .type = "F F F F F",
                   .count = "1 1 1 1 1",
                   .width = 1};
  test::writeText(dir / "t.pcd", two.text() + "1 2 3 0 1\n");
  EXPECT_FALSE(openPointFile(dir / "t.pcd")->info().hasNormals);
  EXPECT_FALSE(readPointFile(dir / "t.pcd").hasNormals());
}

// Fields in a shuffled order with fields the reader does not use: a scalar, a COUNT 3 descriptor
// and "_" padding (which PCL leaves out of binary_compressed blocks).
struct ShuffledPoint {
  float intensity;
  float normalZ;
  double z;
  std::array<float, 3> descriptor;
  int16_t y;
  float x;
  uint32_t rgb;
  float normalX, normalY;
};

const Header kShuffled{.fields = "intensity normal_z z descriptor y _ x rgb normal_x normal_y",
                       .size = "4 4 8 4 2 1 4 4 4 4",
                       .type = "F F F F I U F U F F",
                       .count = "1 1 1 3 1 3 1 1 1 1",
                       .width = 2};

const std::vector<ShuffledPoint> kShuffledPoints = {
    {0.25f, 0.0f, 1e10 + 0.5, {9, 9, 9}, -300, 1.25f, 0x00102030, 0.6f, 0.8f},
    {7.0f, 1.0f, -0.1, {1, 2, 3}, 32767, -2.5f, 0x00FFFFFF, 0.0f, 0.0f}};

Bytes shuffledRecords() {
  Bytes data;
  for (const ShuffledPoint& p : kShuffledPoints) {
    data.le(p.intensity).le(p.normalZ).le(p.z);
    for (float d : p.descriptor) data.le(d);
    data.le(p.y).fill(3, 0xEE).le(p.x).le(p.rgb).le(p.normalX).le(p.normalY);
  }
  return data;
}

Bytes shuffledColumns() {
  Bytes data;
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.intensity);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.normalZ);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.z);
  for (const ShuffledPoint& p : kShuffledPoints)
    for (float d : p.descriptor) data.le(d);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.y);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.x);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.rgb);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.normalX);
  for (const ShuffledPoint& p : kShuffledPoints) data.le(p.normalY);
  return data;
}

std::string shuffledLines() {
  std::string lines;
  for (const ShuffledPoint& p : kShuffledPoints) {
    lines += decimal(p.intensity) + " " + decimal(p.normalZ) + " " + decimal(p.z);
    for (float d : p.descriptor) lines += " " + decimal(d);
    lines += " " + std::to_string(p.y) + " 0 0 0 " + decimal(p.x) + " " + std::to_string(p.rgb) +
             " " + decimal(p.normalX) + " " + decimal(p.normalY) + "\n";
  }
  return lines;
}

TEST(PcdReader, followsAnyFieldOrderAndSkipsUnusedAndMultiValueFields) {
  Header binary = kShuffled;
  binary.data = "binary";
  Header compressed = kShuffled;
  compressed.data = "binary_compressed";
  const std::vector<Bytes> files = {Bytes().text(kShuffled.text() + shuffledLines()),
                                    pcdFile(binary, shuffledRecords()),
                                    pcdFile(compressed, compressedBlock(shuffledColumns()))};
  for (const Bytes& file : files) {
    test::TempDir dir;
    test::writeFile(dir / "s.pcd", file.bytes());
    const auto reader = openPointFile(dir / "s.pcd");
    SCOPED_TRACE(reader->info().format);
    EXPECT_TRUE(reader->info().hasNormals && reader->info().hasColors);
    const PointCloud points = test::readInBatches(dir / "s.pcd", {}, nullptr, 1);
    ASSERT_EQ(points.size(), 2u);
    for (size_t i = 0; i < 2; ++i) {
      const ShuffledPoint& p = kShuffledPoints[i];
      EXPECT_EQ(points.positions[i], glm::dvec3(p.x, p.y, p.z));
      EXPECT_EQ(points.normals[i], glm::vec3(p.normalX, p.normalY, p.normalZ));
    }
    expectColor(points.colors[0], 0x10, 0x20, 0x30);
    expectColor(points.colors[1], 255, 255, 255);
    // ReadOptions::keepExtras: the single-valued field no slot reads, exactly.
    const PointCloud extras = test::readInBatches(dir / "s.pcd", {.columns = "", .keepExtras = true}, nullptr, 1);
    EXPECT_EQ(extras.extraNames, std::vector<std::string>{"intensity"});
    EXPECT_EQ(extras.extras, std::vector<double>({0.25, 7.0}));
    EXPECT_TRUE(points.extras.empty());
  }
}

TEST(PcdReader, acceptsOlderHeadersWithColumnsAndWithoutCountOrHeight) {
  test::TempDir dir;
  test::writeText(dir / "v5.pcd",
                  "VERSION .5\nCOLUMNS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA "
                  "ascii\n1 2 3\n4 5 6\n");
  expectPositions(readPointFile(dir / "v5.pcd"), {{1, 2, 3}, {4, 5, 6}});
}

TEST(PcdReader, readsInBatchesSmallerThanTheFile) {
  // 2500 points, every tenth invalid: batches of 7 must be full until the end.
  std::vector<glm::dvec3> positions;
  std::vector<glm::dvec3> valid;
  for (int i = 0; i < 2500; ++i) {
    positions.push_back(i % 10 == 3 ? glm::dvec3(kNaN) : glm::dvec3(i, -i, 0.5 * i));
    if (i % 10 != 3) valid.push_back(positions.back());
  }
  const Header header{.width = 2500};
  Header binary = header;
  binary.data = "binary";
  Header compressed = header;
  compressed.data = "binary_compressed";
  const std::vector<Bytes> files = {Bytes().text(header.text() + asciiLines(positions)),
                                    pcdFile(binary, floatRecords(positions)),
                                    pcdFile(compressed, compressedBlock(floatColumns(positions)))};
  for (const Bytes& file : files) {
    test::TempDir dir;
    test::writeFile(dir / "m.pcd", file.bytes());
    const auto reader = openPointFile(dir / "m.pcd");
    SCOPED_TRACE(reader->info().format);
    PointCloud first;
    EXPECT_EQ(reader->read(first, 7), 7u);  // point 3 dropped, 7 still returned
    EXPECT_EQ(first.positions[3], glm::dvec3(4, -4, 2));
    ReadStats stats;
    expectPositions(test::readInBatches(dir / "m.pcd", {}, &stats, 7), valid);
    EXPECT_EQ(stats.pointsRead, 2250u);
    EXPECT_EQ(stats.droppedNonFinite, 250u);
  }
}

TEST(PcdReader, readsGzipCompressedFiles) {
  test::TempDir dir;
  test::writeGzip(dir / "z.pcd.gz",
                  pcdFile({.width = 3, .data = "binary"}, floatRecords(kPositions)).bytes());
  test::writeGzip(dir / "c.pcd.gz", pcdFile({.width = 3, .data = "binary_compressed"},
                                            compressedBlock(floatColumns(kPositions)))
                                        .bytes());
  EXPECT_EQ(openPointFile(dir / "z.pcd.gz")->info().format, "pcd-binary");
  expectPositions(readPointFile(dir / "z.pcd.gz"), roundedToFloat(kPositions));
  expectPositions(readPointFile(dir / "c.pcd.gz"), roundedToFloat(kPositions));
}

TEST(PcdReader, headerErrorsNameTheFileAndLine) {
  const auto with = [](auto change) {
    Header header{.width = 1};
    change(header);
    return header.text() + "1 2 3\n";
  };
  const std::vector<std::pair<std::string, std::string>> cases = {
      {with([](Header& h) { h.size = "4 4"; }), "line 4: SIZE has 2 values for the 3 FIELDS"},
      {with([](Header& h) { h.type = "F F"; }), "line 5: TYPE has 2 values for the 3 FIELDS"},
      {with([](Header& h) { h.count = "1 1 1 1"; }), "line 6: COUNT has 4 values for the 3 FIELDS"},
      {with([](Header& h) { h.points = 5; }), "line 10: POINTS 5 is not WIDTH 1 x HEIGHT 1"},
      {with([](Header& h) {
         h.width = uint64_t{1} << 32;
         h.height = uint64_t{1} << 32;
         h.points = 0;
       }),
       "line 10: POINTS 0 is not WIDTH 4294967296 x HEIGHT 4294967296"},
      {with([](Header& h) { h.fields = "x y w"; }),
       "line 3: no field 'z' (x, y and z are required)"},
      {with([](Header& h) { h.size = "4 4 2"; }),
       "line 5: field 'z' has TYPE F with SIZE 2 (supported: I and U of 1, 2, 4 or 8 bytes, F of 4 "
       "or 8)"},
      {with([](Header& h) { h.type = "F F X"; }), "line 5: field 'z' has TYPE X with SIZE 4"},
      {with([](Header& h) {
         h.size = "4 4 3";
         h.type = "F F U";
       }),
       "line 5: field 'z' has TYPE U with SIZE 3"},
      {with([](Header& h) { h.size = "4 4 x"; }),
       "line 4: SIZE value 'x' is not a non-negative integer"},
      {with([](Header& h) { h.data = "zip"; }),
       "line 11: unknown DATA kind 'zip' (known: ascii, binary, binary_compressed)"},
      {with([](Header& h) { h.data = ""; }), "line 11: unknown DATA kind ''"},
      {with([](Header& h) { h.count = "1 1 3"; }),
       "line 6: field 'z' has COUNT 3; coordinates, normals and colors need 1"},
      {with([](Header& h) { h.count = "1 1 0"; }),
       "line 6: field 'z' has COUNT 0 (supported: 1 to 1048576)"},
      {with([](Header& h) {
         h.fields = "x y z rgb";
         h.size = "4 4 4 2";
         h.type = "F F F U";
         h.count = "1 1 1 1";
       }),
       "line 4: packed color field 'rgb' has SIZE 2, not 4"},
      {with([](Header& h) {
         h.fields = "x y z descriptor";
         h.size = "4 4 4 4";
         h.type = "F F F F";
         h.count = "1 1 1 1000000";
       }),
       "line 3: a point of these fields exceeds the 1048576 bytes supported"},
      {"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n",
       "line 5: the PCD header has no WIDTH line before DATA"},
      {"FIELDS x y z\nSIZE 4 4 4\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
       "line 5: the PCD header has no TYPE line before DATA"},
      {"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1 2\nPOINTS 1\nDATA ascii\n",
       "line 4: WIDTH needs one value, not 2"},
      {"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH -1\nPOINTS 1\nDATA ascii\n",
       "line 4: WIDTH value '-1' is not a non-negative integer"},
      {"# comment\n\nFIELDS x y z\nCOLOR 3\n", "line 4: 'COLOR' is not a PCD header keyword"},
      {"FIELDS x y z\nFIELDS x y z\n", "line 2: a second FIELDS line"},
      {"ply but not really\n", "line 1: 'ply' is not a PCD header keyword"},
      {"VERSION 0.7\nFIELDS x y z\n", "byte 25: file ends in the PCD header, before its DATA line"},
  };
  for (const auto& [text, reason] : cases) {
    SCOPED_TRACE(reason);
    const std::string error = pcdError(text);
    EXPECT_NE(error.find("h.pcd: "), std::string::npos) << error;
    EXPECT_NE(error.find(reason), std::string::npos) << error;
  }
}

TEST(PcdReader, asciiDataErrorsNameTheLine) {
  const std::string header = Header{.width = 2}.text();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {header + "1 2\n4 5 6\n", "line 12: expected 3 values, found 2"},
      {header + "1 2 3\n4 5 6 7\n", "line 13: expected 3 values, found 4"},
      {header + "1 x 3\n4 5 6\n", "line 12: value 2 (field 'y') is not a number: 'x'"},
      {header + "1 2 3\n4 5 0x10\n", "line 13: value 3 (field 'z') is not a number: '0x10'"},
      {header + "1 2 3\n", "file ends after 1 of 2 points"},
      {Header{.fields = "x y z rgb",
              .size = "4 4 4 4",
              .type = "F F F U",
              .count = "1 1 1 1",
              .width = 1}
               .text() +
           "1 2 3 red\n",
       "line 12: value 4 (field 'rgb') is not a color: 'red'"},
      {Header{.fields = "x y z rgb",
              .size = "4 4 4 4",
              .type = "F F F U",
              .count = "1 1 1 1",
              .width = 1}
               .text() +
           "1 2 3 4294967296\n",
       "line 12: value 4 (field 'rgb') is not a color: '4294967296'"},
  };
  for (const auto& [text, reason] : cases) {
    SCOPED_TRACE(reason);
    const std::string error = pcdError(text);
    EXPECT_NE(error.find("h.pcd: "), std::string::npos) << error;
    EXPECT_NE(error.find(reason), std::string::npos) << error;
  }
  // The end of the file is an offset: past the last line.
  EXPECT_NE(pcdError(header + "1 2 3\n").find("byte " + std::to_string(header.size() + 6)),
            std::string::npos);
}

TEST(PcdReader, truncatedBinaryDataNamesTheOffsetAndCount) {
  const Header header{.width = 3, .data = "binary"};
  const Bytes whole = pcdFile(header, floatRecords(kPositions));
  const std::vector<std::byte> cut(whole.bytes().begin(), whole.bytes().end() - 5);
  test::TempDir dir;
  test::writeFile(dir / "t.pcd", cut);
  test::writeGzip(dir / "t.pcd.gz", cut);
  for (const char* name : {"t.pcd", "t.pcd.gz"}) {
    SCOPED_TRACE(name);
    try {
      readPointFile(dir / name);
      FAIL() << "no error";
    } catch (const FileError& error) {
      EXPECT_EQ(error.file(), (dir / name).string());
      EXPECT_EQ(error.reason(), "file ends after 2 of 3 points");
      EXPECT_EQ(error.offset(), header.text().size() + 2 * 12);
    }
  }
}

TEST(PcdReader, everyTruncatedPrefixThrowsFileError) {
  const Header binary{.fields = "x y z rgb",
                      .size = "4 4 4 4",
                      .type = "F F F U",
                      .count = "1 1 1 1",
                      .width = 3,
                      .data = "binary"};
  Header compressed = binary;
  compressed.data = "binary_compressed";
  Bytes records;
  Bytes columns = floatColumns(kPositions);
  for (const glm::dvec3& p : kPositions)
    records.le(float(p.x)).le(float(p.y)).le(float(p.z)).le(uint32_t{0x123456});
  for (int i = 0; i < 3; ++i) columns.le(uint32_t{0x123456});
  test::TempDir dir;
  for (const Bytes& file :
       {pcdFile(binary, records), pcdFile(compressed, compressedBlock(columns))}) {
    const std::vector<std::byte>& whole = file.bytes();
    test::writeFile(dir / "whole.pcd", whole);
    ASSERT_EQ(readPointFile(dir / "whole.pcd").size(), 3u);
    for (size_t length = 0; length < whole.size(); ++length) {
      SCOPED_TRACE("prefix of " + std::to_string(length) + " bytes");
      test::writeFile(dir / "cut.pcd", {whole.begin(), whole.begin() + ptrdiff_t(length)});
      EXPECT_THROW(readPointFile(dir / "cut.pcd"), FileError);
    }
  }
}

// A binary_compressed file of kPositions with its block replaced by the given sizes and data.
Bytes withBlock(uint32_t compressedSize, uint32_t uncompressedSize, const Bytes& data,
                uint64_t width = 3) {
  Bytes block;
  block.le(compressedSize).le(uncompressedSize);
  return pcdFile({.width = width, .data = "binary_compressed"}, append(block, data));
}

TEST(PcdReader, compressedBlockSizesAreCheckedBeforeAllocating) {
  const size_t blockAt = Header{.width = 3, .data = "binary_compressed"}.text().size();
  const Bytes valid = compressedBlock(floatColumns(kPositions));
  const uint32_t validSize = uint32_t(valid.size() - 8);
  const Bytes lzf = [&] {
    Bytes data;
    for (size_t i = 8; i < valid.size(); ++i) data.le(valid.bytes()[i]);
    return data;
  }();
  Bytes twoLiteralRuns;  // two LZF literal runs of 32 bytes: 64 bytes, more than the 36 declared
  twoLiteralRuns.le(uint8_t{31}).fill(32, 1).le(uint8_t{31}).fill(32, 2);
  struct Case {
    Bytes file;
    std::string reason;
    uint64_t offset;
  };
  const std::vector<Case> cases = {
      {withBlock(validSize, 40, lzf),
       "the binary_compressed block holds 40 bytes, not POINTS 3 x 12 bytes per point",
       blockAt + 4},
      {withBlock(100, 1200000000, Bytes().fill(100, 0), 100000000),
       "100 LZF-compressed bytes cannot hold the 1200000000 bytes the binary_compressed block "
       "declares",
       0},
      {withBlock(100, 0xFFFFFFF0u, Bytes().fill(100, 0), uint64_t{1} << 40),
       "the binary_compressed block holds 4294967280 bytes, not POINTS 1099511627776 x 12 bytes "
       "per point",
       0},
      {withBlock(validSize + 1000, 36, lzf),
       "file ends inside the binary_compressed block (" + std::to_string(validSize) + " of " +
           std::to_string(validSize + 1000) + " bytes)",
       blockAt + 8 + validSize},
      {withBlock(2, 36, Bytes().le(uint8_t{0x20}).le(uint8_t{0x05})),
       "the LZF data of the binary_compressed block is corrupt", blockAt + 8},
      {withBlock(2, 36, Bytes().le(uint8_t{0}).le(uint8_t{0x41})),
       "the LZF data of the binary_compressed block decompresses to 1 bytes, not the 36 it "
       "declares",
       blockAt + 8},
      {withBlock(66, 36, twoLiteralRuns),
       "the LZF data of the binary_compressed block decompresses to more than the 36 bytes it "
       "declares",
       blockAt + 8},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.reason);
    test::TempDir dir;
    test::writeFile(dir / "c.pcd", c.file.bytes());
    const auto start = std::chrono::steady_clock::now();
    try {
      readPointFile(dir / "c.pcd");
      ADD_FAILURE() << "no error";
    } catch (const FileError& error) {
      EXPECT_EQ(error.reason(), c.reason);
      EXPECT_TRUE(error.offset().has_value());
      if (c.offset != 0) {
        EXPECT_EQ(error.offset(), c.offset);
      }
    }
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  }
}

TEST(PcdReader, hostilePointCountsInBinaryFilesAreTruncationErrors) {
  const Header header{.width = uint64_t{1} << 50, .data = "binary"};
  test::TempDir dir;
  const Bytes file = pcdFile(header, floatRecords(kPositions));
  test::writeFile(dir / "h.pcd", file.bytes());
  test::writeGzip(dir / "h.pcd.gz", file.bytes());
  for (const char* name : {"h.pcd", "h.pcd.gz"}) {
    SCOPED_TRACE(name);
    const auto start = std::chrono::steady_clock::now();
    EXPECT_NE(test::readError(dir / name).find("file ends after 3 of 1125899906842624 points"),
              std::string::npos);
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  }
}

}  // namespace
}  // namespace iso
