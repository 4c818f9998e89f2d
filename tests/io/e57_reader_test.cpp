// The E57 reader on files built byte by byte from ASTM E2807 (e57_file.h): every field encoding,
// spherical coordinates, poses against a brute-force transform, colors and intensity, invalid
// points, packets across pages, hostile files (each refused with its reason), every truncated
// prefix and every damaged byte; then against an independent reader (npm web-e57, through node)
// on writer-made files and, when ISO_E57_SAMPLES names a folder of them, on real E57 files.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <glm/geometric.hpp>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>

#include "iso/quantize.h"
#include "tests/support/e57_file.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using test::E57FieldSpec;
using test::E57Layout;
using test::E57ScanSpec;
using test::E57Spec;
using test::E57Type;

const ReadOptions kWithExtras{.columns = "", .keepExtras = true};

// ---- Building scans ------------------------------------------------------------------------

E57FieldSpec floats(const std::string& name, E57Type type, std::vector<double> values,
                    const std::string& attributes = "") {
  E57FieldSpec f{.name = name, .type = type, .floats = std::move(values)};
  f.attributes = attributes;
  return f;
}

E57FieldSpec integers(const std::string& name, int64_t minimum, int64_t maximum,
                      std::vector<int64_t> values) {
  E57FieldSpec f{.name = name, .type = E57Type::kInteger, .minimum = minimum, .maximum = maximum};
  f.integers = std::move(values);
  return f;
}

E57FieldSpec scaled(const std::string& name, int64_t minimum, int64_t maximum, double scale,
                    double offset, std::vector<int64_t> raw) {
  E57FieldSpec f{.name = name,
                 .type = E57Type::kScaledInteger,
                 .minimum = minimum,
                 .maximum = maximum,
                 .scale = scale,
                 .offset = offset};
  f.integers = std::move(raw);
  return f;
}

std::vector<E57FieldSpec> cartesian(const std::vector<glm::dvec3>& points,
                                    E57Type type = E57Type::kDouble) {
  std::vector<E57FieldSpec> fields;
  const char* names[] = {"cartesianX", "cartesianY", "cartesianZ"};
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<double> values;
    for (const glm::dvec3& p : points) values.push_back(p[axis]);
    fields.push_back(floats(names[axis], type, values));
  }
  return fields;
}

// Deterministic points in a box of half-size `extent` around `centre`.
std::vector<glm::dvec3> randomPoints(size_t count, uint64_t seed, double extent = 10.0,
                                     glm::dvec3 centre = glm::dvec3(0.0)) {
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> uniform(-extent, extent);
  std::vector<glm::dvec3> points(count);
  for (glm::dvec3& p : points)
    p = centre + glm::dvec3(uniform(random), uniform(random), uniform(random));
  return points;
}

E57ScanSpec scanOf(std::vector<E57FieldSpec> fields, const std::string& name = "") {
  return E57ScanSpec{.name = name, .fields = std::move(fields)};
}

E57Spec fileOf(std::vector<E57ScanSpec> scans) { return E57Spec{.scans = std::move(scans)}; }

// ---- Reading ---------------------------------------------------------------------------------

struct E57Read {
  PointCloud points;
  PointFileInfo info;
  ReadStats stats;
};

// Read a whole file in batches of `batch`, checking the batch contract.
E57Read readBytes(const std::vector<std::byte>& file, const ReadOptions& options = {},
                  size_t batch = 1000) {
  test::TempDir dir;
  test::writeFile(dir / "scan.e57", file);
  auto reader = openPointFile(dir / "scan.e57", options);
  E57Read read;
  for (;;) {
    const size_t before = read.points.size();
    const size_t appended = reader->read(read.points, batch);
    EXPECT_LE(appended, batch);
    EXPECT_EQ(read.points.size(), before + appended);
    if (appended == 0) break;
  }
  EXPECT_EQ(read.points.colors.size(), reader->info().hasColors ? read.points.size() : 0u);
  EXPECT_EQ(read.points.extras.size(), read.points.size() * reader->info().extraNames.size());
  read.info = reader->info();
  read.stats = reader->stats();
  return read;
}

E57Read readE57(const E57Spec& spec, const ReadOptions& options = {}, size_t batch = 1000) {
  return readBytes(test::makeE57(spec), options, batch);
}

// The message of the FileError that reading the file throws, "" when it reads.
std::string errorOf(const std::vector<std::byte>& file) {
  test::TempDir dir;
  test::writeFile(dir / "bad.e57", file);
  return test::readError(dir / "bad.e57");
}

std::string errorOf(const E57Spec& spec) { return errorOf(test::makeE57(spec)); }

std::string errorOf(const E57Layout& layout) {
  return errorOf(test::pageE57(layout.logical, layout.pageSize));
}

#define EXPECT_HAS(text, part) EXPECT_NE((text).find(part), std::string::npos) << (text)

// ---- Independent answers ---------------------------------------------------------------------

// The rotation of p by the quaternion q (w, x, y, z) after normalizing it, as q p q* with
// Hamilton products: independent of the reader's rotation matrix.
glm::dvec3 rotated(const std::array<double, 4>& q, const glm::dvec3& p) {
  struct Quaternion {
    double w, x, y, z;
  };
  const auto multiply = [](const Quaternion& a, const Quaternion& b) {
    return Quaternion{a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
                      a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
                      a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
                      a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
  };
  // Scaled first, so that tiny and huge quaternions neither underflow nor overflow.
  const double largest = std::max({std::abs(q[0]), std::abs(q[1]), std::abs(q[2]), std::abs(q[3])});
  const Quaternion s{q[0] / largest, q[1] / largest, q[2] / largest, q[3] / largest};
  const double norm = std::sqrt(s.w * s.w + s.x * s.x + s.y * s.y + s.z * s.z);
  const Quaternion unit{s.w / norm, s.x / norm, s.y / norm, s.z / norm};
  const Quaternion conjugate{unit.w, -unit.x, -unit.y, -unit.z};
  const Quaternion r = multiply(multiply(unit, {0.0, p.x, p.y, p.z}), conjugate);
  return {r.x, r.y, r.z};
}

float linearOf16(int code) {
  const float c = float(code) / 65535.0f;
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

void expectNear(const glm::dvec3& actual, const glm::dvec3& expected, double tolerance,
                const std::string& what) {
  for (int axis = 0; axis < 3; ++axis)
    EXPECT_NEAR(actual[axis], expected[axis], tolerance) << what << " axis " << axis;
}

// ---- Values ----------------------------------------------------------------------------------

TEST(E57Reader, readsCartesianDoublesExactlyAndSinglesAsTheirFloats) {
  const std::vector<glm::dvec3> points = {
      {515123.4567891234, 4918000.123456789, -10.5}, {0.1, -0.2, 0.3}, {1e-300, -1e300, 0.0}};
  for (E57Type type : {E57Type::kDouble, E57Type::kSingle}) {
    SCOPED_TRACE(type == E57Type::kDouble ? "double" : "single");
    std::vector<glm::dvec3> stored = points;
    if (type == E57Type::kSingle) stored.pop_back();  // beyond float's range
    const E57Read read = readE57(fileOf({scanOf(cartesian(stored, type))}));
    EXPECT_EQ(read.info.format, "e57 1.0 (1 scan)");
    EXPECT_EQ(read.info.declaredPoints, stored.size());
    EXPECT_FALSE(read.info.hasColors);
    ASSERT_EQ(read.points.size(), stored.size());
    for (size_t i = 0; i < stored.size(); ++i)
      EXPECT_EQ(read.points.positions[i],
                type == E57Type::kDouble ? stored[i] : test::roundedToFloat(stored[i]))
          << i;
  }
}

TEST(E57Reader, readsScaledIntegersAsRawTimesScalePlusOffset) {
  // 19-bit coordinates of a millimetre grid around a UTM origin.
  const std::vector<int64_t> raw = {-262144, -1, 0, 1, 12345, 262143};
  E57ScanSpec scan = scanOf({scaled("cartesianX", -262144, 262143, 0.001, 515000.0, raw),
                             scaled("cartesianY", -262144, 262143, 0.001, 4918000.0, raw),
                             scaled("cartesianZ", -262144, 262143, 0.25, -3.0, raw)});
  const E57Read read = readE57(fileOf({scan}));
  ASSERT_EQ(read.points.size(), raw.size());
  for (size_t i = 0; i < raw.size(); ++i) {
    const double r = double(raw[i]);
    EXPECT_EQ(read.points.positions[i],
              glm::dvec3(r * 0.001 + 515000.0, r * 0.001 + 4918000.0, r * 0.25 - 3.0));
  }
  expectNear(read.points.positions[4], {515012.345, 4918012.345, 3083.25}, 1e-9, "12345");
}

// Integers of every width from 1 to 64 bits, values at both bounds and between, so that values
// straddle bytes at every bit offset; 58–64 bits take the two-load path.
TEST(E57Reader, readsIntegersOfEveryBitWidthFromOneToSixtyFour) {
  for (int bits = 1; bits <= 64; ++bits) {
    SCOPED_TRACE("bits " + std::to_string(bits));
    const int64_t minimum =
        bits == 64 ? std::numeric_limits<int64_t>::min() : -(int64_t{1} << (bits - 1)) + 3;
    const int64_t maximum = bits == 64 ? std::numeric_limits<int64_t>::max()
                                       : int64_t(uint64_t(minimum) + ((uint64_t{1} << bits) - 1));
    std::vector<int64_t> values = {minimum, maximum, minimum + 1, maximum - 1};
    std::mt19937_64 random{uint64_t(bits)};
    for (int i = 0; i < 37; ++i)
      values.push_back(
          int64_t(uint64_t(minimum) + random() % (uint64_t(maximum) - uint64_t(minimum))));
    const std::vector<double> ys(values.size(), 2.0);
    E57ScanSpec scan =
        scanOf({integers("cartesianX", minimum, maximum, values),
                floats("cartesianY", E57Type::kSingle, ys),
                integers("cartesianZ", 0, 1, std::vector<int64_t>(values.size(), 1))});
    const E57Read read = readE57(fileOf({scan}), {}, 7);
    ASSERT_EQ(read.points.size(), values.size());
    for (size_t i = 0; i < values.size(); ++i)
      EXPECT_EQ(read.points.positions[i], glm::dvec3(double(values[i]), 2.0, 1.0)) << i;
  }
}

TEST(E57Reader, aFieldWhoseMinimumEqualsItsMaximumTakesNoBytesAndHoldsTheMinimum) {
  const std::vector<glm::dvec3> points = randomPoints(50, 1);
  std::vector<E57FieldSpec> fields = cartesian(points);
  fields[2] = scaled("cartesianZ", 7, 7, 0.5, 1.0, std::vector<int64_t>(points.size(), 7));
  ASSERT_EQ(fields[2].bits(), 0u);
  E57ScanSpec scan = scanOf(fields);
  scan.recordsPerPacket = 8;
  const E57Read read = readE57(fileOf({scan}));
  ASSERT_EQ(read.points.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i)
    EXPECT_EQ(read.points.positions[i], glm::dvec3(points[i].x, points[i].y, 4.5));
}

TEST(E57Reader, convertsSphericalCoordinatesToCartesian) {
  const double half = std::numbers::pi / 2;
  const std::vector<std::array<double, 3>> rae = {{2.0, 0.0, 0.0},
                                                  {1.0, half, 0.0},
                                                  {3.0, 1.0, half},
                                                  {4.0, std::numbers::pi, -half / 3},
                                                  {5.5, -2.0, 0.4}};
  std::vector<double> range, azimuth, elevation;
  for (const auto& v : rae) {
    range.push_back(v[0]);
    azimuth.push_back(v[1]);
    elevation.push_back(v[2]);
  }
  E57ScanSpec scan = scanOf({floats("sphericalRange", E57Type::kDouble, range),
                             floats("sphericalAzimuth", E57Type::kDouble, azimuth),
                             floats("sphericalElevation", E57Type::kDouble, elevation)});
  const E57Read read = readE57(fileOf({scan}));
  ASSERT_EQ(read.points.size(), rae.size());
  expectNear(read.points.positions[0], {2, 0, 0}, 1e-15, "along x");
  expectNear(read.points.positions[1], {0, 1, 0}, 1e-15, "along y");
  expectNear(read.points.positions[2], {0, 0, 3}, 1e-15, "up");
  expectNear(read.points.positions[3], {-4 * std::sqrt(3.0) / 2, 0, -2}, 1e-14, "back, down 30°");
  const auto& v = rae[4];
  expectNear(read.points.positions[4],
             {v[0] * std::cos(v[2]) * std::cos(v[1]), v[0] * std::cos(v[2]) * std::sin(v[1]),
              v[0] * std::sin(v[2])},
             1e-14, "general");
}

// Each scan's points in world coordinates: R(q) p + t of its own pose, q normalized. Quaternions
// of any length (one of length 2, one tiny), and scans without a pose or with only a translation.
TEST(E57Reader, appliesEachScansPoseAgainstABruteForceTransform) {
  struct Pose {
    std::optional<std::array<double, 4>> rotation;
    std::optional<std::array<double, 3>> translation;
  };
  const std::vector<Pose> poses = {
      {std::array<double, 4>{1.0, 0.0, 0.0, 1.0}, std::array<double, 3>{10.0, -20.0, 5.0}},
      {std::nullopt, std::nullopt},
      {std::array<double, 4>{0.3, -0.5, 0.7, 0.1}, std::array<double, 3>{-1e5, 2e5, 3.5}},
      {std::array<double, 4>{1e-200, 2e-200, -3e-200, 4e-200}, std::nullopt},
      {std::nullopt, std::array<double, 3>{0.5, 0.25, 0.125}}};
  E57Spec spec;
  std::vector<std::vector<glm::dvec3>> local;
  for (size_t s = 0; s < poses.size(); ++s) {
    local.push_back(randomPoints(20 + s, 100 + s));
    E57ScanSpec scan = scanOf(cartesian(local.back()), "station " + std::to_string(s));
    scan.rotation = poses[s].rotation;
    scan.translation = poses[s].translation;
    spec.scans.push_back(scan);
  }
  const E57Read read = readE57(spec);
  EXPECT_EQ(read.info.format, "e57 1.0 (5 scans)");
  size_t i = 0;
  for (size_t s = 0; s < poses.size(); ++s) {
    for (const glm::dvec3& p : local[s]) {
      ASSERT_LT(i, read.points.size());
      glm::dvec3 expected = poses[s].rotation ? rotated(*poses[s].rotation, p) : p;
      if (poses[s].translation)
        expected += glm::dvec3((*poses[s].translation)[0], (*poses[s].translation)[1],
                               (*poses[s].translation)[2]);
      expectNear(read.points.positions[i++], expected, 1e-9 * (1.0 + glm::length(expected)),
                 "scan " + std::to_string(s));
    }
  }
  EXPECT_EQ(i, read.points.size());
  // A quarter turn about z, analytically: (1, 0, 0) -> (0, 1, 0), then the translation.
  E57ScanSpec turn = scanOf(cartesian({{1.0, 0.0, 0.0}}));
  turn.rotation = std::array<double, 4>{std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)};
  turn.translation = std::array<double, 3>{1.0, 2.0, 3.0};
  expectNear(readE57(fileOf({turn})).points.positions.at(0), {1.0, 3.0, 3.0}, 1e-15, "turn");
}

TEST(E57Reader, readsScansInOrderSkippingScansWithoutRecords) {
  E57Spec spec = fileOf({scanOf(cartesian({{1, 1, 1}, {2, 2, 2}}), "a"),
                         scanOf(cartesian({}), "empty"), scanOf(cartesian({{3, 3, 3}}), "c")});
  const E57Read read = readE57(spec);
  EXPECT_EQ(read.info.format, "e57 1.0 (3 scans)");
  EXPECT_EQ(read.info.declaredPoints, 3u);
  EXPECT_EQ(read.points.positions, (std::vector<glm::dvec3>{{1, 1, 1}, {2, 2, 2}, {3, 3, 3}}));
  EXPECT_TRUE(read.info.notes.empty());
  EXPECT_EQ(readE57(fileOf({})).points.size(), 0u);  // no scan at all
}

// ---- Colors and intensity --------------------------------------------------------------------

std::vector<E57FieldSpec> withColors(std::vector<E57FieldSpec> fields, int64_t minimum,
                                     int64_t maximum,
                                     const std::vector<std::array<int64_t, 3>>& rgb) {
  const char* names[] = {"colorRed", "colorGreen", "colorBlue"};
  for (int c = 0; c < 3; ++c) {
    std::vector<int64_t> values;
    for (const auto& color : rgb) values.push_back(color[size_t(c)]);
    fields.push_back(integers(names[c], minimum, maximum, values));
  }
  return fields;
}

const char* kColorLimits255 =
    "<colorLimits type=\"Structure\"><colorRedMinimum type=\"Integer\">0</colorRedMinimum>"
    "<colorRedMaximum type=\"Integer\">255</colorRedMaximum><colorGreenMinimum "
    "type=\"Integer\"/><colorGreenMaximum type=\"Integer\">255</colorGreenMaximum>"
    "<colorBlueMinimum type=\"Integer\">0</colorBlueMinimum><colorBlueMaximum "
    "type=\"Integer\">255</colorBlueMaximum></colorLimits>\n";

TEST(E57Reader, readsEightBitColorsThroughColorLimitsAsSrgb) {
  const std::vector<std::array<int64_t, 3>> rgb = {{0, 128, 255}, {10, 20, 30}, {255, 255, 255}};
  // Fields declared 0–1023 (10 bits); colorLimits say the values are 0–255.
  E57ScanSpec scan = scanOf(withColors(cartesian({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}), 0, 1023, rgb));
  scan.xml = kColorLimits255;
  const E57Read read = readE57(fileOf({scan}));
  ASSERT_TRUE(read.info.hasColors);
  ASSERT_EQ(read.points.size(), 3u);
  for (size_t i = 0; i < 3; ++i)
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(read.points.colors[i][c], test::linearOf8(int(rgb[i][size_t(c)])), 1e-6);
      EXPECT_EQ(linearToSrgb8(read.points.colors[i][c]), rgb[i][size_t(c)]);
    }
}

TEST(E57Reader, readsColorsByTheirFieldsBoundsWithoutColorLimits) {
  // 16-bit integers 0–65535, and floats with minimum 0 and maximum 1 (and without: also 0–1).
  E57ScanSpec sixteen = scanOf(withColors(cartesian({{0, 0, 0}, {1, 1, 1}}), 0, 65535,
                                          {{0, 32768, 65535}, {257, 1000, 60000}}));
  const E57Read read16 = readE57(fileOf({sixteen}));
  ASSERT_EQ(read16.points.size(), 2u);
  EXPECT_NEAR(read16.points.colors[0].g, linearOf16(32768), 1e-6);
  EXPECT_NEAR(read16.points.colors[1].r, linearOf16(257), 1e-6);
  EXPECT_NEAR(read16.points.colors[1].b, linearOf16(60000), 1e-6);
  EXPECT_EQ(read16.points.colors[0].b, 1.0f);

  std::vector<E57FieldSpec> fields = cartesian({{0, 0, 0}, {1, 1, 1}});
  fields.push_back(
      floats("colorRed", E57Type::kSingle, {0.5, 2.0}, " minimum=\"0\" maximum=\"1\""));
  fields.push_back(floats("colorGreen", E57Type::kDouble, {0.25, -1.0}));
  fields.push_back(
      floats("colorBlue", E57Type::kDouble, {1.0, 0.0}, " minimum=\"0\" maximum=\"2\""));
  const E57Read read = readE57(fileOf({scanOf(fields)}));
  ASSERT_EQ(read.points.size(), 2u);
  EXPECT_NEAR(read.points.colors[0].r, srgbToLinear(0.5f), 2e-5);
  EXPECT_NEAR(read.points.colors[0].g, srgbToLinear(0.25f), 2e-5);
  EXPECT_NEAR(read.points.colors[0].b, srgbToLinear(0.5f), 2e-5);
  EXPECT_EQ(read.points.colors[1], glm::vec3(1.0f, 0.0f, 0.0f));  // clamped
}

TEST(E57Reader, keepsColorsOnlyWhenEveryScanWithPointsHasThem) {
  E57ScanSpec colored = scanOf(withColors(cartesian({{0, 0, 0}}), 0, 255, {{1, 2, 3}}), "colored");
  E57ScanSpec plain = scanOf(cartesian({{1, 1, 1}}), "plain");
  E57ScanSpec emptyPlain = scanOf(cartesian({}), "nothing");
  const E57Read read = readE57(fileOf({colored, plain}));
  EXPECT_FALSE(read.info.hasColors);
  EXPECT_EQ(read.points.size(), 2u);
  ASSERT_EQ(read.info.notes.size(), 1u);
  EXPECT_EQ(read.info.notes[0],
            "colors (colorRed, colorGreen, colorBlue) dropped: scan 2 'plain' has none");
  const E57Read withEmpty = readE57(fileOf({colored, emptyPlain}));
  EXPECT_TRUE(withEmpty.info.hasColors);
  EXPECT_TRUE(withEmpty.info.notes.empty());
}

TEST(E57Reader, givesPointsWithInvalidColorsANeutralGreyAndCountsThem) {
  std::vector<E57FieldSpec> fields = withColors(cartesian({{0, 0, 0}, {1, 1, 1}, {2, 2, 2}}), 0,
                                                255, {{255, 0, 0}, {9, 9, 9}, {0, 0, 255}});
  fields.push_back(integers("isColorInvalid", 0, 1, {0, 1, 1}));
  const E57Read read = readE57(fileOf({scanOf(fields)}));
  ASSERT_EQ(read.points.size(), 3u);
  EXPECT_EQ(read.points.colors[0], glm::vec3(1.0f, 0.0f, 0.0f));
  const float grey = srgbToLinear(0.5f);
  EXPECT_EQ(read.points.colors[1], glm::vec3(grey));
  EXPECT_EQ(read.points.colors[2], glm::vec3(grey));
  EXPECT_EQ(read.info.notes,
            std::vector<std::string>{"2 points marked isColorInvalid given a neutral grey"});
}

TEST(E57Reader, keepsIntensityAsStoredAsAnExtraWithNaNWhereInvalid) {
  std::vector<E57FieldSpec> fields = cartesian({{0, 0, 0}, {1, 1, 1}, {2, 2, 2}});
  fields.push_back(scaled("intensity", -666, 666, 0.1, 0.0, {-666, 5, 666}));
  fields.push_back(integers("isIntensityInvalid", 0, 1, {0, 1, 0}));
  const E57Spec spec = fileOf({scanOf(fields)});
  const E57Read read = readE57(spec, kWithExtras);
  EXPECT_EQ(read.info.extraNames, std::vector<std::string>{"intensity"});
  ASSERT_EQ(read.points.extraNames, std::vector<std::string>{"intensity"});
  ASSERT_EQ(read.points.extras.size(), 3u);
  EXPECT_EQ(read.points.extras[0], -666 * 0.1);
  EXPECT_TRUE(std::isnan(read.points.extras[1]));
  EXPECT_EQ(read.points.extras[2], 666 * 0.1);
  EXPECT_EQ(read.info.notes,
            std::vector<std::string>{"1 points marked isIntensityInvalid have intensity NaN"});
  const E57Read without = readE57(spec);
  EXPECT_TRUE(without.info.extraNames.empty());
  EXPECT_TRUE(without.points.extras.empty());
  EXPECT_TRUE(without.info.notes.empty());
}

// ---- Dropped points --------------------------------------------------------------------------

TEST(E57Reader, dropsPointsMarkedInvalidAndCountsThemInANote) {
  std::vector<E57FieldSpec> fields = cartesian({{0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {3, 3, 3}});
  fields.push_back(integers("cartesianInvalidState", 0, 2, {0, 1, 2, 0}));
  E57ScanSpec spherical = scanOf({floats("sphericalRange", E57Type::kSingle, {1, 2, 3}),
                                  floats("sphericalAzimuth", E57Type::kSingle, {0, 0, 0}),
                                  floats("sphericalElevation", E57Type::kSingle, {0, 0, 0}),
                                  integers("sphericalInvalidState", 0, 2, {2, 0, 1})});
  const E57Read read = readE57(fileOf({scanOf(fields), spherical}));
  EXPECT_EQ(read.points.positions, (std::vector<glm::dvec3>{{0, 0, 0}, {3, 3, 3}, {2, 0, 0}}));
  EXPECT_EQ(read.info.notes,
            std::vector<std::string>{"4 points marked invalid (cartesianInvalidState or "
                                     "sphericalInvalidState not 0) dropped"});
  EXPECT_EQ(read.stats.pointsRead, 3u);
}

TEST(E57Reader, dropsNonFiniteCoordinatesAndCountsThem) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const E57Read read =
      readE57(fileOf({scanOf(cartesian({{1, 2, 3}, {nan, 0, 0}, {0, inf, 0}, {4, 5, 6}}))}));
  EXPECT_EQ(read.points.positions, (std::vector<glm::dvec3>{{1, 2, 3}, {4, 5, 6}}));
  EXPECT_EQ(read.stats.droppedNonFinite, 2u);
  EXPECT_EQ(read.stats.pointsRead, 2u);
}

// ---- Packets and pages -----------------------------------------------------------------------

// Many packets, each crossing page boundaries, for several page sizes and batch sizes: every
// point comes back, in order, with its color.
TEST(E57Reader, readsManyPacketsThatCrossPageBoundaries) {
  const std::vector<glm::dvec3> points = randomPoints(3000, 7, 200.0);
  std::vector<int64_t> x, y, z;
  std::vector<std::array<int64_t, 3>> rgb;
  for (size_t i = 0; i < points.size(); ++i) {
    x.push_back(std::llround(points[i].x * 1000));
    y.push_back(std::llround(points[i].y * 1000));
    z.push_back(std::llround(points[i].z * 1000));
    rgb.push_back({int64_t(i % 256), int64_t(i * 7 % 256), int64_t(255 - i % 256)});
  }
  E57ScanSpec scan = scanOf(withColors({scaled("cartesianX", -200000, 200000, 0.001, 0.0, x),
                                        scaled("cartesianY", -200000, 200000, 0.001, 0.0, y),
                                        scaled("cartesianZ", -200000, 200000, 0.001, 0.0, z)},
                                       0, 255, rgb));
  for (uint64_t pageSize : {uint64_t{64}, uint64_t{1024}, uint64_t{4096}}) {
    for (size_t perPacket : {size_t{1}, size_t{13}, size_t{0}}) {
      SCOPED_TRACE("page size " + std::to_string(pageSize) + ", records per packet " +
                   std::to_string(perPacket));
      scan.recordsPerPacket = perPacket;
      E57Spec spec = fileOf({scan});
      spec.pageSize = pageSize;
      const E57Read read = readE57(spec, {}, perPacket == 13 ? 4097 : 500);
      ASSERT_EQ(read.points.size(), points.size());
      for (size_t i = 0; i < points.size(); ++i) {
        ASSERT_EQ(read.points.positions[i],
                  glm::dvec3(double(x[i]) * 0.001, double(y[i]) * 0.001, double(z[i]) * 0.001))
            << i;
        ASSERT_EQ(linearToSrgb8(read.points.colors[i].g), rgb[i][1]) << i;
      }
    }
  }
}

TEST(E57Reader, skipsIndexAndEmptyPackets) {
  const std::vector<glm::dvec3> points = randomPoints(100, 3);
  E57ScanSpec scan = scanOf(cartesian(points, E57Type::kSingle));
  scan.recordsPerPacket = 9;
  scan.emptyAndIndexPackets = true;
  const E57Read read = readE57(fileOf({scan}));
  ASSERT_EQ(read.points.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i)
    EXPECT_EQ(read.points.positions[i], test::roundedToFloat(points[i]));
}

// The bitpack bytestreams are one stream per field across packets: a field may arrive packets
// after the others (here field f of the data of packet k comes in packet k + 2f), and values
// straddle packet boundaries.
TEST(E57Reader, decodesFieldsWhoseBytesArriveInDifferentPackets) {
  const std::vector<glm::dvec3> points = randomPoints(500, 5);
  std::vector<int64_t> state(points.size(), 0);
  std::vector<E57FieldSpec> fields = cartesian(points);
  fields[1] = floats("cartesianY", E57Type::kSingle, fields[1].floats);
  fields.push_back(integers("cartesianInvalidState", 0, 2, state));
  E57Layout layout;
  {
    E57Spec spec = fileOf({scanOf(fields)});
    spec.scans[0].recordsPerPacket = 500;
    layout = test::layoutE57(spec);
  }
  // Rebuild the one data packet as staggered packets by hand: 10 bytes of x per packet, 3 of y,
  // 1 of the 2-bit states, and z only after all of x.
  std::vector<std::vector<std::byte>> streams;
  for (const E57FieldSpec& f : fields) streams.push_back(test::e57::bitpack(f));
  const std::array<size_t, 4> chunk = {10, 3, 20000, 1};
  std::vector<size_t> sent(4, 0);
  std::vector<std::byte> packets;
  while (sent[0] < streams[0].size() || sent[1] < streams[1].size() ||
         sent[2] < streams[2].size() || sent[3] < streams[3].size()) {
    const size_t at = packets.size();
    std::array<size_t, 4> take{};
    for (size_t f = 0; f < 4; ++f) {
      const bool waits = f == 2 && sent[0] < streams[0].size();
      take[f] = waits ? 0 : std::min(chunk[f], streams[f].size() - sent[f]);
    }
    packets.push_back(std::byte{1});
    packets.push_back(std::byte{0});
    test::e57::putLE(packets, 0, 2);
    test::e57::putLE(packets, 4, 2);
    for (size_t f = 0; f < 4; ++f) test::e57::putLE(packets, take[f], 2);
    for (size_t f = 0; f < 4; ++f) {
      packets.insert(packets.end(), streams[f].begin() + ptrdiff_t(sent[f]),
                     streams[f].begin() + ptrdiff_t(sent[f] + take[f]));
      sent[f] += take[f];
    }
    test::e57::pad4(packets);
    test::e57::patchLE(packets, at + 2, packets.size() - at - 1, 2);
  }
  // Put them where the single packet was: the section grows, so lay the file out again around it.
  E57Spec spec = fileOf({scanOf(fields)});
  spec.scans[0].recordsPerPacket = 500;
  const uint64_t sectionAt = layout.sectionAt[0];
  const uint64_t packetAt = layout.dataPacketsAt[0][0];
  std::vector<std::byte> logical(layout.logical.begin(),
                                 layout.logical.begin() + ptrdiff_t(packetAt));
  logical.insert(logical.end(), packets.begin(), packets.end());
  test::e57::patchLE(logical, sectionAt + 8, logical.size() - sectionAt, 8);
  // The XML follows, at a new offset.
  test::e57::pad4(logical);
  const uint64_t xmlAt = logical.size();
  for (char c : layout.xml) logical.push_back(std::byte(c));
  const uint64_t pages = (logical.size() + 1019) / 1020;
  test::e57::patchLE(logical, 16, pages * 1024, 8);
  test::e57::patchLE(logical, 24, layout.physical(xmlAt), 8);
  const E57Read read = readBytes(test::pageE57(logical, 1024), {}, 64);
  ASSERT_EQ(read.points.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i)
    EXPECT_EQ(read.points.positions[i],
              glm::dvec3(points[i].x, double(float(points[i].y)), points[i].z))
        << i;
}

// ---- Hostile and damaged files ---------------------------------------------------------------

E57Spec smallFile() {
  E57ScanSpec a = scanOf(withColors(cartesian(randomPoints(40, 11)), 0, 255,
                                    std::vector<std::array<int64_t, 3>>(40, {1, 2, 3})),
                         "Station 1");
  a.recordsPerPacket = 16;
  a.rotation = std::array<double, 4>{0.5, 0.5, 0.5, 0.5};
  E57ScanSpec b = scanOf(withColors(cartesian(randomPoints(30, 12), E57Type::kSingle), 0, 255,
                                    std::vector<std::array<int64_t, 3>>(30, {4, 5, 6})),
                         "Station 3");
  b.recordsPerPacket = 7;
  return fileOf({a, b});
}

TEST(E57Reader, refusesFilesWithoutTheSignature) {
  test::TempDir dir;
  test::writeText(dir / "a.e57", "ASTM-E56 and more text to make it long enough for a header...");
  EXPECT_HAS(test::readError(dir / "a.e57"), "not an E57 file: no ASTM-E57 signature");
}

TEST(E57Reader, refusesTruncatedFilesSayingSo) {
  const std::vector<std::byte> file = test::makeE57(smallFile());
  ASSERT_EQ(file.size() % 1024, 0u);
  std::vector<std::byte> cut(file.begin(), file.end() - 1024);  // a whole page less
  EXPECT_HAS(errorOf(cut), "byte 16: the header gives the file's length as " +
                               std::to_string(file.size()) + " bytes, but it has " +
                               std::to_string(cut.size()) + ": it is truncated or damaged");
  cut.resize(file.size() - 100);
  EXPECT_HAS(errorOf(cut), "are not a whole number of 1024-byte pages: it is truncated or damaged");
  cut.resize(30);
  EXPECT_HAS(errorOf(cut), "byte 30: file ends inside the 48-byte E57 header (30 bytes)");
}

// Sections are read out of order and the file's length is checked against its size: a gzip
// stream allows neither cheaply.
TEST(E57Reader, refusesGzipCompressedFilesSayingToDecompressThem) {
  test::TempDir dir;
  test::writeGzip(dir / "scan.e57.gz", test::makeE57(smallFile()));
  EXPECT_HAS(test::readError(dir / "scan.e57.gz"),
             "byte 0: gzip-compressed E57 files are not supported: decompress it first (gunzip)");
}

TEST(E57Reader, refusesUnsupportedVersionsAndPageSizes) {
  E57Spec spec = smallFile();
  spec.versionMajor = 2;
  EXPECT_HAS(errorOf(spec), "byte 8: unsupported E57 version 2.0 (supported: 1.x)");
  spec.versionMajor = 1;
  spec.versionMinor = 3;  // minor versions are compatible
  EXPECT_EQ(readE57(spec).info.format, "e57 1.3 (2 scans)");
  for (uint64_t pageSize : {uint64_t{8}, uint64_t{60}, uint64_t{1026}, uint64_t{2} << 20}) {
    E57Layout layout = test::layoutE57(smallFile());
    test::e57::patchLE(layout.logical, 40, pageSize, 8);
    EXPECT_HAS(errorOf(layout), "byte 40: unsupported page size " + std::to_string(pageSize) +
                                    " (supported: a multiple of 4 from 64 bytes to 1 MiB");
  }
}

TEST(E57Reader, refusesPagesWhoseChecksumFailsNamingThePage) {
  const E57Layout layout = test::layoutE57(smallFile());
  const std::vector<std::byte> file = test::pageE57(layout.logical, 1024);
  // A byte of the XML, and a byte of the second scan's data.
  for (uint64_t logical : {layout.xmlAt + 100, layout.dataPacketsAt[1][1] + 20}) {
    std::vector<std::byte> damaged = file;
    const uint64_t physical = layout.physical(logical);
    damaged[physical] ^= std::byte{0x10};
    const uint64_t page = physical / 1024;
    EXPECT_HAS(errorOf(damaged), "byte " + std::to_string(page * 1024) + ": page " +
                                     std::to_string(page) + ": CRC-32C mismatch");
  }
  // A damaged checksum is a mismatch too.
  std::vector<std::byte> damaged = file;
  damaged[1023] ^= std::byte{1};
  EXPECT_HAS(errorOf(damaged), "byte 0: page 0: CRC-32C mismatch");
}

TEST(E57Reader, refusesARecordCountThatTheDataDoesNotHold) {
  E57Spec spec = smallFile();
  spec.scans[1].recordCount = 31;  // one more than there are
  EXPECT_HAS(errorOf(spec), "scan 2 'Station 3': its section ends after 30 of 31 records");
  spec.scans[1].recordCount = 3000;  // more than its section's bytes can hold
  EXPECT_HAS(errorOf(spec), "scan 2 'Station 3': its section's ");
  EXPECT_HAS(errorOf(spec), " bytes cannot hold 3,000 records of 120 bits");
}

TEST(E57Reader, refusesPacketsAndBuffersPastTheirSectionOrPacket) {
  const E57Layout good = test::layoutE57(smallFile());
  const uint64_t packet = good.dataPacketsAt[0][1];
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, packet + 2, 65535, 2);  // length 65536
    EXPECT_HAS(errorOf(layout), "byte " + std::to_string(layout.physical(packet)) +
                                    ": scan 1 'Station 1': a packet of 65536 bytes runs past "
                                    "the end of its section");
  }
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, packet + 2, 1021, 2);  // length 1022
    EXPECT_HAS(errorOf(layout),
               "scan 1 'Station 1': a packet's length 1022 is not a multiple of 4");
  }
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, packet + 6 + 2, 60000, 2);  // cartesianY's buffer
    EXPECT_HAS(errorOf(layout),
               "scan 1 'Station 1': the buffer of bytestream 1 ('cartesianY', "
               "60000 bytes) runs past the end of its");
  }
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, packet + 4, 7, 2);
    EXPECT_HAS(errorOf(layout), "a data packet has 7 bytestreams, but the prototype has 6 fields");
  }
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, packet + 4, 600, 2);
    EXPECT_HAS(errorOf(layout), "a data packet has 600 bytestreams");
  }
  {
    E57Layout layout = good;
    layout.logical[packet] = std::byte{7};
    EXPECT_HAS(errorOf(layout), "byte " + std::to_string(layout.physical(packet)) +
                                    ": scan 1 'Station 1': unknown packet type 7 (known: 0 "
                                    "index, 1 data, 2 empty)");
  }
  {
    E57Layout layout = good;  // a section that ends inside its last packet
    const uint64_t section = layout.sectionAt[0];
    const uint64_t length = layout.sectionAt[1] - 4 - section;  // 4 bytes short of its end
    test::e57::patchLE(layout.logical, section + 8, length, 8);
    EXPECT_HAS(errorOf(layout), "scan 1 'Station 1': a packet of ");
  }
}

TEST(E57Reader, refusesHostileSectionHeaders) {
  const E57Layout good = test::layoutE57(smallFile());
  const uint64_t section = good.sectionAt[1];
  {
    E57Layout layout = good;
    layout.logical[section] = std::byte{2};
    EXPECT_HAS(errorOf(layout), "scan 2 'Station 3': its points' section has id 2, not 1");
  }
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, section + 8, uint64_t{1} << 62, 8);
    EXPECT_HAS(errorOf(layout),
               "its section's length 4611686018427387904 is past the end of the file");
  }
  {
    E57Layout layout = good;
    test::e57::patchLE(layout.logical, section + 16, layout.physical(good.xmlAt + 100), 8);
    EXPECT_HAS(errorOf(layout), "scan 2 'Station 3': its first data packet's offset");
  }
  // Two scans whose points claim the same section.
  E57Spec twice = smallFile();
  twice.scans[1] = twice.scans[0];
  twice.scans[1].name = "copy";
  E57Layout layout = test::layoutE57(twice);
  const std::string first =
      "fileOffset=\"" + std::to_string(layout.physical(layout.sectionAt[0])) + "\"";
  const std::string second =
      "fileOffset=\"" + std::to_string(layout.physical(layout.sectionAt[1])) + "\"";
  std::string xml = layout.xml;
  ASSERT_NE(xml.find(second), std::string::npos);
  xml.replace(xml.find(second), second.size(),
              first + std::string(second.size() - first.size(), ' '));
  std::copy(xml.begin(), xml.end(), reinterpret_cast<char*>(layout.logical.data() + layout.xmlAt));
  EXPECT_HAS(errorOf(layout),
             "the points of scan 1 'Station 1' and scan 2 'copy' share bytes of the file");
  // A fileOffset inside a page's checksum.
  E57Spec spec = smallFile();
  spec.xml = test::layoutE57(spec).xml;
  const std::string offset =
      "fileOffset=\"" + std::to_string(layout.physical(layout.sectionAt[0])) + "\"";
  spec.xml->replace(spec.xml->find(offset), offset.size(), "fileOffset=\"1022\"");
  EXPECT_HAS(errorOf(spec),
             "byte 1022: scan 1 'Station 1': its points' fileOffset 1022 is past the "
             "end of the file or inside a page checksum");
}

// The XML of a one-scan file with `points` as the prototype's fields and `more` inside the scan.
std::string xmlWith(const std::string& prototype, const std::string& more = "",
                    const std::string& points = "fileOffset=\"48\" recordCount=\"0\"") {
  return "<?xml version=\"1.0\"?>\n<e57Root type=\"Structure\">\n<data3D type=\"Vector\">"
         "<vectorChild type=\"Structure\"><name type=\"String\">Scan A</name>" +
         more + "<points type=\"CompressedVector\" " + points + "><prototype type=\"Structure\">" +
         prototype + "</prototype></points></vectorChild></data3D></e57Root>\n";
}

const char* kXyz =
    "<cartesianX type=\"Float\"/><cartesianY type=\"Float\"/><cartesianZ type=\"Float\"/>";

std::string xmlError(const std::string& xml) {
  E57Spec spec;
  spec.xml = xml;
  return errorOf(spec);
}

TEST(E57Reader, refusesDoctypesAndEntitiesBeforeExpandingAny) {
  std::string laughs = "<?xml version=\"1.0\"?>\n<!DOCTYPE lolz [\n<!ENTITY lol \"lol\">\n";
  for (int i = 1; i <= 9; ++i)
    laughs += "<!ENTITY lol" + std::to_string(i) + " \"" + [&] {
      std::string ten;
      for (int k = 0; k < 10; ++k)
        ten += "&lol" + (i == 1 ? std::string() : std::to_string(i - 1)) + ";";
      return ten;
    }() + "\">\n";
  laughs += "]>\n<e57Root type=\"Structure\"><guid type=\"String\">&lol9;</guid></e57Root>\n";
  const auto start = std::chrono::steady_clock::now();
  EXPECT_HAS(xmlError(laughs),
             "XML line 2: the XML section has a DOCTYPE declaration, which E57 "
             "never needs (refused, so that no entity is expanded)");
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
  // An entity reference without a declaration is expat's "undefined entity".
  EXPECT_HAS(xmlError(xmlWith(kXyz, "<description type=\"String\">&lol9;</description>")),
             "undefined entity");
}

TEST(E57Reader, refusesDeepNestingAndHugeCounts) {
  std::string deep = "<?xml version=\"1.0\"?><e57Root>";
  for (int i = 0; i < 100; ++i) deep += "<a>";
  EXPECT_HAS(xmlError(deep), "XML line 1: elements nest deeper than 64 levels");

  std::string many = "<?xml version=\"1.0\"?>\n<e57Root><data3D>";
  const std::string scan =
      "<vectorChild><points type=\"CompressedVector\" fileOffset=\"0\" recordCount=\"0\">"
      "<prototype>" +
      std::string(kXyz) + "</prototype></points></vectorChild>\n";
  for (int i = 0; i <= 65536; ++i) many += scan;
  many += "</data3D></e57Root>";
  EXPECT_HAS(xmlError(many),
             "XML line 65538: data3D holds more than 65,536 point clouds, the most "
             "supported");

  std::string fields = kXyz;
  for (int i = 0; i < 1100; ++i) fields += "<f" + std::to_string(i) + " type=\"Float\"/>";
  EXPECT_HAS(xmlError(xmlWith(fields)), "scan 1 'Scan A': its prototype has more than 1024 fields");

  E57Layout layout = test::layoutE57(smallFile());
  test::e57::patchLE(layout.logical, 32, (uint64_t{64} << 20) + 1, 8);
  EXPECT_HAS(errorOf(layout),
             "the XML section has 67,108,865 bytes, more than the 64.0 MiB supported");
  test::e57::patchLE(layout.logical, 32, 0, 8);
  EXPECT_HAS(errorOf(layout), "the XML section is empty");
  test::e57::patchLE(layout.logical, 32, 1 << 20, 8);
  EXPECT_HAS(errorOf(layout), "the XML section (1,048,576 bytes) runs past the end of the file");
}

TEST(E57Reader, refusesMalformedXmlWithItsLine) {
  EXPECT_HAS(xmlError("<?xml version=\"1.0\"?>\n<e57Root>\n<data3D></e57Root>"),
             "XML line 3: mismatched tag");
  EXPECT_HAS(xmlError("<?xml version=\"1.0\"?>\n<root/>"),
             "XML line 2: the root element is 'root', not e57Root");
  EXPECT_HAS(xmlError("<?xml version=\"1.0\"?>\n<e57Root>"), "no element found");
}

TEST(E57Reader, refusesMalformedNumbers) {
  EXPECT_HAS(xmlError(xmlWith(kXyz, "", "fileOffset=\"48\" recordCount=\"12x\"")),
             "scan 1 'Scan A': its points' recordCount '12x' is not a non-negative integer");
  EXPECT_HAS(xmlError(xmlWith(kXyz, "", "fileOffset=\"-5\" recordCount=\"1\"")),
             "its points' fileOffset '-5' is not a non-negative integer");
  EXPECT_HAS(xmlError(xmlWith(kXyz, "", "recordCount=\"1\"")),
             "scan 1 'Scan A': its points element has no fileOffset attribute");
  EXPECT_HAS(xmlError(xmlWith(kXyz,
                              "<pose type=\"Structure\"><rotation type=\"Structure\"><w "
                              "type=\"Float\">abc</w></rotation></pose>")),
             "scan 1 'Scan A': 'w' holds 'abc', not a finite number");
  EXPECT_HAS(xmlError(xmlWith("<cartesianX type=\"Integer\" minimum=\"1.5\"/>")),
             "the minimum of 'cartesianX' is '1.5', not a 64-bit integer");
  EXPECT_HAS(xmlError(xmlWith("<cartesianX type=\"Integer\" minimum=\"5\" maximum=\"4\"/>")),
             "its prototype field 'cartesianX' has maximum 4 below its minimum 5");
  EXPECT_HAS(xmlError(xmlWith("<cartesianX type=\"ScaledInteger\" scale=\"inf\"/>")),
             "the scale of 'cartesianX' is 'inf', not a finite number");
  EXPECT_HAS(xmlError(xmlWith("<cartesianX type=\"Float\" precision=\"half\"/>")),
             "its prototype field 'cartesianX' has precision 'half' (known: single, double)");
}

TEST(E57Reader, refusesPrototypesItCannotRead) {
  EXPECT_HAS(xmlError(xmlWith(std::string(kXyz) + "<comment type=\"String\"/>")),
             "scan 1 'Scan A': its prototype field 'comment' has type 'String', which this reader "
             "cannot decode (supported: Float, Integer, ScaledInteger)");
  EXPECT_HAS(xmlError(xmlWith("<cartesianX type=\"Float\"><a/></cartesianX>")),
             "its prototype field 'cartesianX' holds an element ('a'): nested fields are not "
             "supported");
  const std::string missing =
      "its prototype has neither cartesianX, cartesianY and cartesianZ nor "
      "sphericalRange, sphericalAzimuth and sphericalElevation";
  EXPECT_HAS(xmlError(xmlWith("<cartesianX type=\"Float\"/><cartesianY type=\"Float\"/>")),
             "scan 1 'Scan A': " + missing);
  EXPECT_HAS(
      xmlError(xmlWith("<sphericalRange type=\"Float\"/><sphericalAzimuth type=\"Float\"/>")),
      missing);
  EXPECT_HAS(xmlError(xmlWith(std::string(kXyz) + "<cartesianX type=\"Float\"/>")),
             "its prototype has two 'cartesianX' fields");
  EXPECT_HAS(xmlError("<?xml version=\"1.0\"?><e57Root><data3D><vectorChild><name>n</name>"
                      "</vectorChild></data3D></e57Root>"),
             "scan 1 'n': it has no points element (CompressedVector)");
  EXPECT_HAS(xmlError("<?xml version=\"1.0\"?><e57Root><data3D><vectorChild><points "
                      "type=\"CompressedVector\" fileOffset=\"0\" recordCount=\"0\"/>"
                      "</vectorChild></data3D></e57Root>"),
             "scan 1: its points element has no prototype");
  E57Spec spec = smallFile();
  spec.scans[1].codecs = "<vectorChild type=\"Structure\"/>";
  EXPECT_HAS(errorOf(spec),
             "scan 2 'Station 3': its points name a codec ('vectorChild'): only "
             "the default bitpack codec is supported");
  // Every field constant: no bytes say how many records there are.
  std::vector<E57FieldSpec> constant;
  for (const char* name : {"cartesianX", "cartesianY", "cartesianZ"})
    constant.push_back(integers(name, 3, 3, {3, 3}));
  EXPECT_HAS(errorOf(fileOf({scanOf(constant)})),
             "every field of its prototype is constant (0 bits per record)");
}

TEST(E57Reader, refusesPosesThatAreNoRotation) {
  E57Spec spec = smallFile();
  spec.scans[1].rotation = std::array<double, 4>{0.0, 0.0, 0.0, 0.0};
  EXPECT_HAS(errorOf(spec), "scan 2 'Station 3': its pose's rotation quaternion is zero");
  EXPECT_HAS(xmlError(xmlWith(kXyz,
                              "<pose type=\"Structure\"><rotation type=\"Structure\"><w "
                              "type=\"Float\">1</w><x type=\"Float\"/><y type=\"Float\"/>"
                              "</rotation></pose>")),
             "scan 1 'Scan A': its pose's rotation has no z");
  EXPECT_HAS(xmlError(xmlWith(kXyz, "<pose><rotation><w type=\"String\">1</w></rotation></pose>")),
             "'w' has type 'String', not Float, Integer or ScaledInteger");
}

// A file that stores all of one field before the others would need all of it in memory: refused
// once the waiting bytes pass 64 MiB.
TEST(E57Reader, refusesFilesWhoseFieldsDoNotInterleaveBeyondTheMemoryBound) {
  const size_t count = (size_t{64} << 20) / 8 + 100000;
  // The XML of a one-record scan of a double x and 1-bit y and z, declaring `count` records.
  std::string xml =
      test::layoutE57(
          fileOf({scanOf({floats("cartesianX", E57Type::kDouble, {0}),
                          integers("cartesianY", 0, 1, {0}), integers("cartesianZ", 0, 1, {0})})}))
          .xml;
  const std::string declared = "recordCount=\"1\"";
  xml.replace(xml.find(declared), declared.size(), "recordCount=\"" + std::to_string(count) + "\"");
  // Its section at byte 48 as in that file: all of x (1.5 each) in packets of 65,000 bytes, then
  // y (ones) and z (zeros).
  std::vector<std::byte> x;
  for (size_t i = 0; i < count; ++i) test::e57::putLE(x, std::bit_cast<uint64_t>(1.5), 8);
  const std::array<std::vector<std::byte>, 3> streams = {
      x, std::vector<std::byte>((count + 7) / 8, std::byte{0xFF}),
      std::vector<std::byte>((count + 7) / 8, std::byte{0})};
  std::vector<std::byte> logical(48);
  const uint64_t section = logical.size();
  logical.push_back(std::byte{1});
  logical.insert(logical.end(), 31, std::byte{0});
  for (size_t f = 0; f < 3; ++f) {
    for (size_t sent = 0; sent < streams[f].size();) {
      const size_t take = std::min<size_t>(65000, streams[f].size() - sent);
      const size_t at = logical.size();
      logical.push_back(std::byte{1});
      logical.push_back(std::byte{0});
      test::e57::putLE(logical, 0, 2);
      test::e57::putLE(logical, 3, 2);
      for (size_t g = 0; g < 3; ++g) test::e57::putLE(logical, g == f ? take : 0, 2);
      logical.insert(logical.end(), streams[f].begin() + ptrdiff_t(sent),
                     streams[f].begin() + ptrdiff_t(sent + take));
      sent += take;
      test::e57::pad4(logical);
      test::e57::patchLE(logical, at + 2, logical.size() - at - 1, 2);
    }
  }
  const E57Layout pages;  // 1024-byte pages
  test::e57::patchLE(logical, section + 8, logical.size() - section, 8);
  test::e57::patchLE(logical, section + 16, pages.physical(section + 32), 8);
  const uint64_t xmlAt = logical.size();
  for (char c : xml) logical.push_back(std::byte(c));
  std::vector<std::byte> header;
  for (char c : std::string("ASTM-E57")) header.push_back(std::byte(c));
  test::e57::putLE(header, 1, 4);
  test::e57::putLE(header, 0, 4);
  test::e57::putLE(header, (logical.size() + 1019) / 1020 * 1024, 8);
  test::e57::putLE(header, pages.physical(xmlAt), 8);
  test::e57::putLE(header, xml.size(), 8);
  test::e57::putLE(header, 1024, 8);
  std::copy(header.begin(), header.end(), logical.begin());
  EXPECT_HAS(errorOf(test::pageE57(logical, 1024)),
             "scan 1: field 'cartesianX' has 64.0 MiB of values waiting for the other fields' "
             "(more than the 64.0 MiB held for all fields)");
}

// ---- Every prefix, every byte ----------------------------------------------------------------

// A file cut anywhere is refused with a FileError (E57 declares its length), never a crash.
TEST(E57Reader, everyTruncatedPrefixIsAFileError) {
  E57Spec spec = smallFile();
  spec.pageSize = 256;
  const std::vector<std::byte> file = test::makeE57(spec);
  ASSERT_EQ(readBytes(file).points.size(), 70u);
  test::TempDir dir;
  for (size_t size = 0; size < file.size(); ++size) {
    test::writeFile(dir / "cut.e57",
                    std::vector<std::byte>(file.begin(), file.begin() + ptrdiff_t(size)));
    try {
      readPointFile(dir / "cut.e57");
      ADD_FAILURE() << "a prefix of " << size << " bytes was read";
    } catch (const FileError&) {
    }
  }
}

// Every byte of the logical stream changed, with the checksums made right again so that the
// change reaches the parsers: each file reads or is refused with a FileError, never anything else.
TEST(E57Reader, everyDamagedByteIsReadOrRefusedWithAFileError) {
  const E57Layout layout = test::layoutE57(smallFile());
  test::TempDir dir;
  size_t refused = 0;
  for (size_t at = 0; at < layout.logical.size(); ++at) {
    for (uint8_t change : {uint8_t{0xFF}, uint8_t{0x01}}) {
      std::vector<std::byte> logical = layout.logical;
      logical[at] ^= std::byte{change};
      test::writeFile(dir / "d.e57", test::pageE57(logical, layout.pageSize));
      try {
        const PointCloud points = readPointFile(dir / "d.e57", kWithExtras);
        EXPECT_LE(points.size(), 70u) << at;
      } catch (const FileError&) {
        ++refused;
      } catch (const std::exception& e) {
        ADD_FAILURE() << "byte " << at << " ^ " << int(change) << ": " << e.what();
      }
    }
  }
  EXPECT_GT(refused, 100u);
}

// ---- Against an independent reader -----------------------------------------------------------

struct CommandResult {
  int exitCode = -1;
  std::string output;
};

CommandResult run(const std::string& command) {
  CommandResult result;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return result;
  char buffer[4096];
  size_t got = 0;
  while ((got = fread(buffer, 1, sizeof buffer, pipe)) > 0) result.output.append(buffer, got);
  const int status = pclose(pipe);
  result.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

std::string quoted(const std::filesystem::path& path) { return "'" + path.string() + "'"; }

// Why web-e57 cannot run here, or "" when it can.
std::string whyNoWebE57() {
  if (run("node --version").exitCode != 0) return "node is not installed";
  const std::filesystem::path module =
      std::filesystem::path(ISO_WEB_TOOLS_DIR) / "node_modules" / "web-e57" / "e57_bg.wasm";
  if (!std::filesystem::exists(module))
    return "npm web-e57 is not installed (" + module.string() + "; `tools/run setup` installs it)";
  return "";
}

// web-e57's XYZ lines of a file: x y z, then r g b (0–255) when the point has a color.
std::vector<std::vector<double>> webE57Points(const std::filesystem::path& e57,
                                              std::string* error) {
  const std::filesystem::path xyz = e57.string() + ".xyz";
  const CommandResult result =
      run("node " + quoted(std::filesystem::path(ISO_SOURCE_DIR) / "tests/io/e57_to_xyz.mjs") +
          " " + quoted(ISO_WEB_TOOLS_DIR) + " " + quoted(e57) + " " + quoted(xyz));
  std::vector<std::vector<double>> lines;
  if (result.exitCode != 0) {
    *error = result.output;
    return lines;
  }
  std::ifstream in(xyz);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream values(line);
    std::vector<double> row;
    for (double v = 0; values >> v;) row.push_back(v);
    lines.push_back(row);
  }
  return lines;
}

struct Agreement {
  size_t points = 0;
  double maxCoordinateDifference = 0.0;
  int maxColorDifference = 0;  // in 8-bit codes
};

// Compare the reader's points with web-e57's lines, point by point.
Agreement compare(const PointCloud& ours, const std::vector<std::vector<double>>& theirs) {
  Agreement agreement;
  EXPECT_EQ(ours.size(), theirs.size());
  agreement.points = std::min(ours.size(), theirs.size());
  for (size_t i = 0; i < agreement.points; ++i) {
    if (theirs[i].size() < 3) {
      ADD_FAILURE() << "line " << i + 1 << " of web-e57's XYZ has no point";
      break;
    }
    for (int axis = 0; axis < 3; ++axis)
      agreement.maxCoordinateDifference =
          std::max(agreement.maxCoordinateDifference,
                   std::abs(ours.positions[i][axis] - theirs[i][size_t(axis)]));
    if (ours.hasColors() && theirs[i].size() == 6)
      for (int c = 0; c < 3; ++c)
        agreement.maxColorDifference = std::max(
            agreement.maxColorDifference,
            std::abs(int(linearToSrgb8(ours.colors[i][c])) - int(theirs[i][size_t(3 + c)])));
  }
  return agreement;
}

Agreement compareWithWebE57(const std::filesystem::path& e57) {
  std::string error;
  const std::vector<std::vector<double>> theirs = webE57Points(e57, &error);
  EXPECT_TRUE(error.empty()) << error;
  return compare(readPointFile(e57), theirs);
}

// The files the cross-check uses: several scans with poses (float, scaled integer, spherical,
// with colors), invalid points, and many packets over pages.
E57Spec crossCheckFile() {
  E57Spec spec = smallFile();
  // Unit quaternions: web-e57 uses a quaternion as it is, the reader normalizes it.
  const double norm = std::sqrt(0.95);
  spec.scans[1].rotation = std::array<double, 4>{0.9 / norm, 0.1 / norm, -0.3 / norm, 0.2 / norm};
  spec.scans[1].translation = std::array<double, 3>{1000.5, -2000.25, 30.0};
  const std::vector<glm::dvec3> points = randomPoints(2000, 21, 50.0);
  std::vector<int64_t> x, y, z, state;
  std::vector<std::array<int64_t, 3>> rgb;
  for (size_t i = 0; i < points.size(); ++i) {
    x.push_back(std::llround(points[i].x * 1e4));
    y.push_back(std::llround(points[i].y * 1e4));
    z.push_back(std::llround(points[i].z * 1e4));
    state.push_back(i % 10 == 3 ? 2 : 0);
    rgb.push_back({int64_t(i * 3 % 256), int64_t(i * 5 % 256), int64_t(i * 11 % 256)});
  }
  std::vector<E57FieldSpec> fields =
      withColors({scaled("cartesianX", -500000, 500000, 1e-4, 0.0, x),
                  scaled("cartesianY", -500000, 500000, 1e-4, 0.0, y),
                  scaled("cartesianZ", -500000, 500000, 1e-4, 0.0, z)},
                 0, 255, rgb);
  fields.push_back(integers("cartesianInvalidState", 0, 2, state));
  E57ScanSpec scaledScan = scanOf(fields, "scaled");
  scaledScan.recordsPerPacket = 333;
  scaledScan.rotation = std::array<double, 4>{0.0, 0.0, 0.0, 1.0};
  scaledScan.translation = std::array<double, 3>{-5.0, 5.0, 0.5};
  scaledScan.xml = kColorLimits255;
  spec.scans.push_back(scaledScan);
  std::vector<double> range, azimuth, elevation;
  std::vector<int64_t> sphericalState;
  std::vector<std::array<int64_t, 3>> sphericalRgb;
  for (int i = 0; i < 500; ++i) {
    range.push_back(1.0 + 0.01 * i);
    azimuth.push_back(-3.0 + 0.012 * i);
    elevation.push_back(-1.2 + 0.0048 * i);
    sphericalState.push_back(i % 7 == 0 ? 1 : 0);
    sphericalRgb.push_back({int64_t(i % 256), 128, 255 - int64_t(i % 256)});
  }
  std::vector<E57FieldSpec> sphericalFields =
      withColors({floats("sphericalRange", E57Type::kSingle, range),
                  floats("sphericalAzimuth", E57Type::kDouble, azimuth),
                  floats("sphericalElevation", E57Type::kDouble, elevation)},
                 0, 255, sphericalRgb);
  sphericalFields.push_back(integers("sphericalInvalidState", 0, 2, sphericalState));
  E57ScanSpec sphericalScan = scanOf(sphericalFields, "spherical");
  sphericalScan.rotation = std::array<double, 4>{std::sqrt(0.5), 0.0, 0.0, -std::sqrt(0.5)};
  sphericalScan.translation = std::array<double, 3>{0.0, 0.0, 1.75};
  spec.scans.push_back(sphericalScan);
  return spec;
}

TEST(E57Reader, agreesWithWebE57OnWriterMadeFiles) {
  if (const std::string why = whyNoWebE57(); !why.empty()) GTEST_SKIP() << why;
  test::TempDir dir;
  const E57Spec spec = crossCheckFile();
  test::writeFile(dir / "cross.e57", test::makeE57(spec));
  const Agreement agreement = compareWithWebE57(dir / "cross.e57");
  std::printf(
      "web-e57 on writer-made cross.e57: %zu points, max coordinate difference %.3g, max "
      "color difference %d\n",
      agreement.points, agreement.maxCoordinateDifference, agreement.maxColorDifference);
  RecordProperty("points", std::to_string(agreement.points));
  EXPECT_EQ(agreement.points, 40u + 30u + 1800u + 428u);
  EXPECT_LE(agreement.maxCoordinateDifference, 1e-9);
  EXPECT_LE(agreement.maxColorDifference, 1);
  // The committed sample too (ScaledInteger and spherical single coordinates, two poses).
  std::filesystem::copy_file(std::filesystem::path(ISO_TEST_DATA_DIR) / "e57" / "two-scans.e57",
                             dir / "two-scans.e57");
  const Agreement sample = compareWithWebE57(dir / "two-scans.e57");
  std::printf(
      "web-e57 on two-scans.e57: %zu points, max coordinate difference %.3g, max color "
      "difference %d\n",
      sample.points, sample.maxCoordinateDifference, sample.maxColorDifference);
  EXPECT_EQ(sample.points, 1000u);
  EXPECT_LE(sample.maxCoordinateDifference, 1e-9);
  EXPECT_LE(sample.maxColorDifference, 1);
}

// ISO_E57_SAMPLES names a folder of real E57 files (the e57 crate's testdata): the reader agrees
// with web-e57 on each that both read, and refuses corrupt_crc.e57.
TEST(E57Reader, agreesWithWebE57OnRealSamples) {
  const char* folder = std::getenv("ISO_E57_SAMPLES");
  if (folder == nullptr || !std::filesystem::is_directory(folder))
    GTEST_SKIP() << "set ISO_E57_SAMPLES to a folder of .e57 files to compare them with web-e57";
  if (const std::string why = whyNoWebE57(); !why.empty()) GTEST_SKIP() << why;
  test::TempDir dir;
  size_t compared = 0;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    if (entry.path().extension() != ".e57") continue;
    const std::string name = entry.path().filename().string();
    const std::string ourError = test::readError(entry.path());
    std::string theirError;
    std::filesystem::copy_file(entry.path(), dir / name);
    const std::vector<std::vector<double>> theirs = webE57Points(dir / name, &theirError);
    if (name == "corrupt_crc.e57") {
      EXPECT_HAS(ourError, "CRC-32C mismatch");
      continue;
    }
    if (!ourError.empty() || !theirError.empty()) {
      std::printf(
          "%s: not compared (ours: %s; web-e57: %s)\n", name.c_str(),
          ourError.empty() ? "read" : ourError.c_str(),
          theirError.empty() ? "read" : theirError.substr(0, theirError.find('\n')).c_str());
      EXPECT_TRUE(ourError.empty()) << ourError;
      continue;
    }
    const Agreement agreement = compare(readPointFile(dir / name), theirs);
    std::printf("%s: %zu points, max coordinate difference %.3g, max color difference %d\n",
                name.c_str(), agreement.points, agreement.maxCoordinateDifference,
                agreement.maxColorDifference);
    EXPECT_LE(agreement.maxCoordinateDifference, 1e-9) << name;
    EXPECT_LE(agreement.maxColorDifference, 1) << name;
    ++compared;
  }
  EXPECT_GT(compared, 0u);
}

// ---- The committed sample --------------------------------------------------------------------

// tests/data/e57/two-scans.e57, which CLI tests read: two scans with poses, one Cartesian with
// colors and intensity, one spherical with colors and intensity. Regenerate it with
// ISO_WRITE_E57_SAMPLE=1 (see tests/data/e57/README.md).
E57Spec twoScansSample() {
  std::vector<int64_t> x, y, z, intensity;
  std::vector<std::array<int64_t, 3>> rgb;
  for (int i = 0; i < 600; ++i) {  // a 1 m square of a plane, mm coordinates
    x.push_back((i % 30) * 33);
    y.push_back((i / 30) * 50);
    z.push_back(100 + (i % 30) * (i / 30) % 17);
    intensity.push_back(i % 2048);
    rgb.push_back({int64_t(i % 30 * 8), int64_t(i / 30 * 12), 200});
  }
  std::vector<E57FieldSpec> first = withColors(
      {scaled("cartesianX", 0, 1000, 0.001, 0.0, x), scaled("cartesianY", 0, 1000, 0.001, 0.0, y),
       scaled("cartesianZ", 0, 1000, 0.001, 0.0, z)},
      0, 255, rgb);
  first.push_back(integers("intensity", 0, 2047, intensity));
  E57ScanSpec a = scanOf(first, "Station 1");
  a.xml = kColorLimits255;
  a.rotation = std::array<double, 4>{1.0, 0.0, 0.0, 0.0};
  a.translation = std::array<double, 3>{100.0, 200.0, 10.0};
  std::vector<double> range, azimuth, elevation, level;
  std::vector<std::array<int64_t, 3>> colors;
  for (int i = 0; i < 400; ++i) {  // a cone of rays at 2–4 m
    range.push_back(2.0 + 0.005 * i);
    azimuth.push_back(0.0157 * i);
    elevation.push_back(-0.3 + 0.0015 * i);
    level.push_back(0.25 + 0.001 * i);
    colors.push_back({255, int64_t(i % 200), 40});
  }
  std::vector<E57FieldSpec> second =
      withColors({floats("sphericalRange", E57Type::kSingle, range),
                  floats("sphericalAzimuth", E57Type::kSingle, azimuth),
                  floats("sphericalElevation", E57Type::kSingle, elevation)},
                 0, 255, colors);
  second.push_back(floats("intensity", E57Type::kSingle, level, " minimum=\"0\" maximum=\"1\""));
  E57ScanSpec b = scanOf(second, "Station 2");
  b.rotation = std::array<double, 4>{std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)};  // 90° about z
  b.translation = std::array<double, 3>{101.0, 201.0, 11.5};
  b.recordsPerPacket = 150;
  return fileOf({a, b});
}

TEST(E57Reader, theCommittedSampleIsWhatTheWriterMakesAndReads) {
  const std::filesystem::path sample =
      std::filesystem::path(ISO_TEST_DATA_DIR) / "e57" / "two-scans.e57";
  const std::vector<std::byte> made = test::makeE57(twoScansSample());
  if (std::getenv("ISO_WRITE_E57_SAMPLE") != nullptr) test::writeFile(sample, made);
  ASSERT_TRUE(std::filesystem::exists(sample)) << sample;
  EXPECT_TRUE(test::readFile(sample) == made) << "regenerate with ISO_WRITE_E57_SAMPLE=1";
  const auto reader = openPointFile(sample, kWithExtras);
  EXPECT_EQ(reader->info().format, "e57 1.0 (2 scans)");
  EXPECT_EQ(reader->info().declaredPoints, 1000u);
  EXPECT_TRUE(reader->info().hasColors);
  EXPECT_EQ(reader->info().extraNames, std::vector<std::string>{"intensity"});
  const PointCloud points = readPointFile(sample, kWithExtras);
  ASSERT_EQ(points.size(), 1000u);
  EXPECT_EQ(points.positions[31], glm::dvec3(100.033, 200.05, 10.101));
  // Spherical point 0 of station 2 (2 m at azimuth 0, elevation -0.3): turned to y, translated.
  expectNear(points.positions[600], {101.0, 201.0 + 2 * std::cos(0.3), 11.5 - 2 * std::sin(0.3)},
             1e-6, "station 2, point 0");
  EXPECT_EQ(points.extras[31], 31.0f);
  EXPECT_EQ(points.extras[600], 0.25f);
}

// ---- Speed -----------------------------------------------------------------------------------

// Typical prototypes (scaled-integer or float coordinates, 8-bit colors, intensity) decode at
// several million points a second; about 20 M/s is expected in a release build.
TEST(E57Reader, decodesMillionsOfPointsASecond) {
  const size_t count = 2'000'000;
  std::vector<int64_t> coordinate(count), intensity(count);
  std::vector<std::array<int64_t, 3>> rgb(count);
  for (size_t i = 0; i < count; ++i) {
    coordinate[i] = int64_t(i * 2654435761u % 1000000);
    intensity[i] = int64_t(i % 4096);
    rgb[i] = {int64_t(i % 256), int64_t(i / 256 % 256), 77};
  }
  std::vector<E57FieldSpec> fields =
      withColors({scaled("cartesianX", 0, 999999, 1e-3, 0, coordinate),
                  scaled("cartesianY", 0, 999999, 1e-3, 0, coordinate),
                  scaled("cartesianZ", 0, 999999, 1e-3, 0, coordinate)},
                 0, 255, rgb);
  fields.push_back(integers("intensity", 0, 4095, intensity));
  test::TempDir dir;
  test::writeFile(dir / "big.e57", test::makeE57(fileOf({scanOf(fields)})));
  const auto start = std::chrono::steady_clock::now();
  const PointCloud points = readPointFile(dir / "big.e57", kWithExtras);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_EQ(points.size(), count);
  EXPECT_EQ(points.positions[count - 1].x, double(coordinate[count - 1]) * 1e-3);
  const double rate = double(count) / seconds;
  RecordProperty("points_per_second", std::to_string(rate));
  std::printf("E57: %.1f M points/s\n", rate / 1e6);
  EXPECT_GT(rate, 1e6);  // generous for a loaded machine
}

}  // namespace
}  // namespace iso
