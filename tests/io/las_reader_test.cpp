// The LAS reader on files built byte by byte from the ASPRS LAS 1.4 specification (R15): versions
// 1.2–1.4, point formats 0–10, scale and offset, 8- and 16-bit colors, extra bytes, VLRs,
// compressed formats sent to the LAZ reader, truncation and hostile headers.
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>

#include "iso/quantize.h"
#include "tests/io/io_test_util.h"
#include "tests/io/las_file.h"

namespace iso {
namespace {

using test::Bytes;

using test::LasPoint;
using test::LasRecord;
using test::LasSpec;
using test::makeLas;
constexpr const auto& kRgbOffset = test::kLasRgbOffset;

// Public header offsets used to make headers hostile.
constexpr size_t kVersionMajorAt = 24;
constexpr size_t kHeaderSizeAt = 94;
constexpr size_t kPointDataOffsetAt = 96;
constexpr size_t kPointFormatAt = 104;
constexpr size_t kRecordLengthAt = 105;
constexpr size_t kLegacyCountAt = 107;
constexpr size_t kScaleAt = 131;
constexpr size_t kCount64At = 247;

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

// ReadOptions::keepExtras: intensity, return number, classification and (where the format has
// one) GPS time, from the fields where each format puts them; the other bits of their bytes are
// not read (scan direction and edge flags, the classification's flags of formats 0-5).
TEST(LasReader, keepsIntensityReturnNumberClassificationAndGpsTimeAsExtras) {
  for (int format = 0; format <= 10; ++format) {
    SCOPED_TRACE(format);
    LasSpec spec{.minor = format >= 6 ? 4 : 2, .format = format};
    const bool extended = format >= 6;
    for (int i = 0; i < 3; ++i) {
      LasPoint p{.x = i, .y = 2 * i, .z = 3 * i, .fields = true};
      p.intensity = uint16_t(65535 - 1000 * i);
      p.returns = uint8_t(0xF0 | (i + 1));  // number of returns and flags above
      p.classification = uint8_t(extended ? 200 + i : 0xE0 | (2 + i));  // flags in bits 5-7
      p.gpsTime = 3.0e8 + 0.000125 * i;
      spec.points.push_back(p);
    }
    test::TempDir dir;
    test::writeFile(dir / "e.las", makeLas(spec).bytes());
    const PointCloud points = readPointFile(dir / "e.las", {.columns = "", .keepExtras = true});
    const bool gps = format != 0 && format != 2;
    std::vector<std::string> names = {"intensity", "return_number", "classification"};
    if (gps) names.push_back("gps_time");
    ASSERT_EQ(points.extraNames, names);
    ASSERT_EQ(points.extras.size(), 3 * names.size());
    for (size_t i = 0; i < 3; ++i) {
      const double* e = points.extras.data() + i * names.size();
      EXPECT_EQ(e[0], 65535 - 1000 * double(i));
      EXPECT_EQ(e[1], double(extended ? (0xF0 | (i + 1)) & 15 : (i + 1)));
      EXPECT_EQ(e[2], double(extended ? 200 + i : 2 + i));
      if (gps) {
        EXPECT_EQ(e[3], 3.0e8 + 0.000125 * double(i));
      }
    }
    EXPECT_TRUE(readPointFile(dir / "e.las").extras.empty());
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

// Many scanners store 8-bit codes times 256 (every low byte 0): each code comes back exactly, so
// that white is 255 and not 254 (65280 / 65535 · 255 = 254.0).
TEST(LasReader, readsEightBitCodesTimes256AsExactEightBitCodes) {
  test::TempDir dir;
  for (int format : {2, 3, 7}) {
    SCOPED_TRACE("format " + std::to_string(format));
    LasSpec spec{.minor = format >= 6 ? 4 : 2, .format = format};
    const auto code = [](int c, int channel) { return (c * (1 + 36 * channel) + channel) % 256; };
    for (int c = 0; c < 256; ++c)
      spec.points.push_back({c, 2 * c, -c, uint16_t(code(c, 0) * 256), uint16_t(code(c, 1) * 256),
                             uint16_t(code(c, 2) * 256)});
    test::writeFile(dir / "c.las", makeLas(spec).bytes());
    const auto reader = openPointFile(dir / "c.las");
    ASSERT_EQ(reader->info().notes.size(), 1u);
    EXPECT_NE(reader->info().notes[0].find("8-bit codes times 256"), std::string::npos);
    const PointCloud points = test::readInBatches(dir / "c.las", {}, nullptr, 100);
    ASSERT_EQ(points.size(), 256u);
    for (int c = 0; c < 256; ++c) {
      for (int channel = 0; channel < 3; ++channel) {
        EXPECT_NEAR(points.colors[size_t(c)][channel], test::linearOf8(code(c, channel)), 1e-6);
        EXPECT_EQ(linearToSrgb8(points.colors[size_t(c)][channel]), code(c, channel)) << c;
      }
    }
    EXPECT_EQ(points.colors[0].r, 0.0f);
    EXPECT_EQ(points.colors[255].r, 1.0f);  // code 255 of channel 0: white
  }
}

// Past the probed first 64k points, a value with low bits in a file of 8-bit codes times 256 is
// rounded to the nearest code.
TEST(LasReader, roundsLaterValuesWithLowBitsOfEightBitTimes256Files) {
  LasSpec spec{.format = 2};
  spec.points.assign(65536, {1, 2, 3, 255 * 256, 0, 7 * 256});
  spec.points.push_back({4, 5, 6, 0x80FF, 0x807F, 0xFFFF});
  test::TempDir dir;
  test::writeFile(dir / "r.las", makeLas(spec).bytes());
  const PointCloud points = readPointFile(dir / "r.las");
  ASSERT_EQ(points.size(), 65537u);
  EXPECT_EQ(linearToSrgb8(points.colors[0].r), 255);
  EXPECT_EQ(linearToSrgb8(points.colors[0].b), 7);
  EXPECT_EQ(linearToSrgb8(points.colors.back().r), 0x81);  // 0x80FF / 256 = 128.996
  EXPECT_EQ(linearToSrgb8(points.colors.back().g), 0x80);  // 0x807F / 256 = 128.496
  EXPECT_EQ(linearToSrgb8(points.colors.back().b), 255);   // 65535 / 256 = 256.0: clamped
}

// True 16-bit colors (some low byte not 0) keep their 16 bits; their 8-bit code is the usual
// rounding, v / 257 to nearest.
TEST(LasReader, readsSixteenBitColorsWithTheUsualRoundingToEightBits) {
  LasSpec spec{.format = 3};
  std::vector<uint16_t> values;
  for (uint32_t v = 0; v <= 65535; v += 97) values.push_back(uint16_t(v));
  for (uint16_t v : {uint16_t{65535}, uint16_t{65280}, uint16_t{257 * 128}, uint16_t{1}})
    values.push_back(v);
  for (uint16_t v : values)
    spec.points.push_back({0, 0, 0, v, uint16_t(65535 - v), uint16_t(v * 7u)});
  test::TempDir dir;
  test::writeFile(dir / "s.las", makeLas(spec).bytes());
  EXPECT_TRUE(openPointFile(dir / "s.las")->info().notes.empty());
  const PointCloud points = readPointFile(dir / "s.las");
  ASSERT_EQ(points.size(), values.size());
  for (size_t i = 0; i < values.size(); ++i) {
    const uint16_t v[3] = {values[i], uint16_t(65535 - values[i]), uint16_t(values[i] * 7u)};
    for (int channel = 0; channel < 3; ++channel) {
      EXPECT_FLOAT_EQ(points.colors[i][channel], linearOf16(v[channel]));
      EXPECT_EQ(linearToSrgb8(points.colors[i][channel]), std::lround(v[channel] / 257.0))
          << v[channel];
    }
  }
  EXPECT_EQ(linearToSrgb8(points.colors[values.size() - 3].r), 254);  // 65280: not 8-bit × 256
}

// LAS 1.4 point formats 6–10 with extra bytes after the standard record, described by an Extra
// Bytes VLR (LASF_Spec 4): positions and colors (7, 8, 10) are read, the extra bytes skipped.
TEST(LasReader, readsExtendedPointFormatsWithExtraBytes) {
  test::TempDir dir;
  for (int format = 6; format <= 10; ++format) {
    SCOPED_TRACE("format " + std::to_string(format));
    LasSpec spec{.minor = 4,
                 .format = format,
                 .extraBytes = 4 + 2 + 8,
                 .scale = {0.001, 0.002, 0.0005},
                 .offset = {515000.0, 4918000.0, 2000.0}};
    spec.vlrs = {test::lasExtraBytesRecord({{9, "reflectance"}, {3, "deviation"}, {10, "range"}})};
    spec.points = samplePoints();
    const Bytes file = makeLas(spec);
    EXPECT_EQ(file.size(), 375u + 54 + 3 * 192 + 3 * (test::kLasStandardSize[format] + 14u));
    test::writeFile(dir / "e.las", file.bytes());
    const auto reader = openPointFile(dir / "e.las");
    EXPECT_EQ(reader->info().hasColors, kRgbOffset[format] != 0);
    EXPECT_FALSE(reader->info().crs.has_value());
    EXPECT_TRUE(reader->info().notes.empty());
    const PointCloud points = test::readInBatches(dir / "e.las", {}, nullptr, 2);
    ASSERT_EQ(points.size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(points.positions[i], expectedPosition(spec, spec.points[i]));
      if (kRgbOffset[format] == 0) continue;
      EXPECT_FLOAT_EQ(points.colors[i].r, linearOf16(spec.points[i].red));
      EXPECT_FLOAT_EQ(points.colors[i].g, linearOf16(spec.points[i].green));
      EXPECT_FLOAT_EQ(points.colors[i].b, linearOf16(spec.points[i].blue));
    }
  }
}

constexpr std::string_view kUtm12Wkt =
    R"(PROJCS["WGS 84 / UTM zone 12N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",)"
    R"(6378137,298.257223563]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],)"
    R"(PROJECTION["Transverse_Mercator"],PARAMETER["central_meridian",-111],UNIT["metre",1],)"
    R"(AUTHORITY["EPSG","32612"]])";

TEST(LasReader, keepsTheWktOfAProjectionVlr) {
  LasSpec spec{.format = 1};
  spec.points = samplePoints();
  spec.vlrs = {{"iso_test", 7, std::vector<std::byte>(40, std::byte{'"'})},
               test::lasWktRecord(kUtm12Wkt)};
  test::TempDir dir;
  test::writeFile(dir / "w.las", makeLas(spec).bytes());
  const auto reader = openPointFile(dir / "w.las");
  ASSERT_TRUE(reader->info().crs.has_value());
  const CoordinateSystem& crs = *reader->info().crs;
  EXPECT_EQ(crs.wkt, kUtm12Wkt);
  EXPECT_EQ(crs.name, "WGS 84 / UTM zone 12N");
  EXPECT_EQ(crs.epsg, 32612u);  // the authority of the root element
  EXPECT_EQ(crs.source, "VLR LASF_Projection 2112 (OGC WKT)");
  EXPECT_TRUE(reader->info().notes.empty());
  const PointCloud points = readPointFile(dir / "w.las");
  ASSERT_EQ(points.size(), 3u);
  EXPECT_EQ(points.positions[2], expectedPosition(spec, spec.points[2]));

  // WKT 2 names its authority ID; a nested element's is not the system's; none at all.
  const std::pair<std::string, std::optional<uint32_t>> cases[] = {
      {R"(PROJCRS["x",BASEGEOGCRS["y",ID["EPSG",4326]],ID["EPSG",26912]])", 26912},
      {R"(PROJCS["x",GEOGCS["y",AUTHORITY["EPSG","4326"]],UNIT["m",1]])", std::nullopt},
      {R"(PROJCS["a ""quoted"" AUTHORITY[",AUTHORITY["ESRI","102100"]])", std::nullopt},
      {R"(LOCAL_CS["site grid"])", std::nullopt}};
  for (const auto& [wkt, epsg] : cases) {
    SCOPED_TRACE(wkt);
    spec.vlrs = {test::lasWktRecord(wkt)};
    test::writeFile(dir / "w.las", makeLas(spec).bytes());
    const auto other = openPointFile(dir / "w.las");
    ASSERT_TRUE(other->info().crs.has_value());
    EXPECT_EQ(other->info().crs->epsg, epsg);
    EXPECT_EQ(other->info().crs->wkt, wkt);
  }
}

TEST(LasReader, givesTheEpsgCodesAndCitationOfGeoTiffKeys) {
  LasSpec spec{.format = 0};
  spec.points = samplePoints();
  // GTModelType projected, ProjectedCSType 32612, PCS citation in the ASCII parameters, vertical
  // CS 5703 (NAVD88 height).
  const std::string ascii = "WGS 84|WGS 84 / UTM zone 12N|";
  spec.vlrs = {test::lasGeoAsciiRecord(ascii), test::lasGeoKeysRecord({{1024, 0, 1, 1},
                                                                       {2048, 0, 1, 4326},
                                                                       {2049, 34737, 7, 0},
                                                                       {3072, 0, 1, 32612},
                                                                       {3073, 34737, 22, 7},
                                                                       {4096, 0, 1, 5703}})};
  test::TempDir dir;
  test::writeFile(dir / "g.las", makeLas(spec).bytes());
  auto reader = openPointFile(dir / "g.las");
  ASSERT_TRUE(reader->info().crs.has_value());
  EXPECT_EQ(reader->info().crs->epsg, 32612u);  // the projected system before the geographic one
  EXPECT_EQ(reader->info().crs->verticalEpsg, 5703u);
  EXPECT_EQ(reader->info().crs->name, "WGS 84 / UTM zone 12N");
  EXPECT_EQ(reader->info().crs->wkt, "");
  EXPECT_EQ(reader->info().crs->source, "VLR LASF_Projection 34735 (GeoTIFF keys)");
  EXPECT_TRUE(reader->info().notes.empty());

  // Geographic only, with the GT citation; then both WKT and keys.
  spec.vlrs = {test::lasGeoKeysRecord({{1024, 0, 1, 2}, {1026, 34737, 7, 0}, {2048, 0, 1, 4326}}),
               test::lasGeoAsciiRecord(ascii), test::lasWktRecord(kUtm12Wkt)};
  test::writeFile(dir / "g.las", makeLas(spec).bytes());
  reader = openPointFile(dir / "g.las");
  ASSERT_TRUE(reader->info().crs.has_value());
  EXPECT_EQ(reader->info().crs->epsg, 4326u);
  EXPECT_FALSE(reader->info().crs->verticalEpsg.has_value());
  EXPECT_EQ(reader->info().crs->name, "WGS 84");
  EXPECT_EQ(reader->info().crs->wkt, kUtm12Wkt);
  EXPECT_EQ(reader->info().crs->source,
            "VLR LASF_Projection 34735 (GeoTIFF keys), VLR LASF_Projection 2112 (OGC WKT)");
}

TEST(LasReader, userDefinedOrBrokenGeoTiffKeysGiveNoCodeAndANote) {
  LasSpec spec{.format = 0};
  spec.points = samplePoints();
  test::TempDir dir;
  const auto read = [&](std::vector<LasRecord> vlrs) {
    spec.vlrs = std::move(vlrs);
    test::writeFile(dir / "u.las", makeLas(spec).bytes());
    auto reader = openPointFile(dir / "u.las");
    EXPECT_EQ(readPointFile(dir / "u.las").size(), 3u);
    return std::pair(reader->info().crs, reader->info().notes);
  };
  auto [crs, notes] = read({test::lasGeoKeysRecord({{3072, 0, 1, 32767}, {2048, 0, 1, 0}})});
  EXPECT_FALSE(crs.has_value());
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("no EPSG code"), std::string::npos) << notes[0];

  // A directory that announces more keys than it holds: those it holds are read.
  LasRecord keys = test::lasGeoKeysRecord({{3072, 0, 1, 26912}});
  keys.payload[6] = std::byte{9};
  std::tie(crs, notes) = read({keys});
  ASSERT_TRUE(crs.has_value());
  EXPECT_EQ(crs->epsg, 26912u);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("announces 9 keys but holds 1"), std::string::npos) << notes[0];

  // Not a version 1 directory; a citation pointing past the ASCII parameters.
  std::tie(crs, notes) =
      read({{"LASF_Projection", 34735, std::vector<std::byte>(10, std::byte{0x55})}});
  EXPECT_FALSE(crs.has_value());
  ASSERT_EQ(notes.size(), 2u);
  EXPECT_NE(notes[0].find("not one of version 1"), std::string::npos) << notes[0];
  std::tie(crs, notes) = read({test::lasGeoKeysRecord({{3072, 0, 1, 32612}, {3073, 34737, 50, 0}}),
                               test::lasGeoAsciiRecord("short|")});
  ASSERT_TRUE(crs.has_value());
  EXPECT_EQ(crs->epsg, 32612u);
  EXPECT_EQ(crs->name, "");
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("GeoTIFF key 3073 refers to ASCII parameters"), std::string::npos);
}

// LAS 1.4 may keep the WKT in an EVLR after the point data; found in plain and gzip files.
TEST(LasReader, keepsTheWktOfALas14Evlr) {
  LasSpec spec{.minor = 4, .format = 7, .extraBytes = 2};
  spec.points = samplePoints();
  spec.evlrs = {{"iso_test", 1, std::vector<std::byte>(300, std::byte{1})},
                test::lasWktRecord(kUtm12Wkt)};
  const Bytes file = makeLas(spec);
  test::TempDir dir;
  test::writeFile(dir / "e.las", file.bytes());
  test::writeGzip(dir / "e.las.gz", file.bytes());
  for (const char* name : {"e.las", "e.las.gz"}) {
    SCOPED_TRACE(name);
    const auto reader = openPointFile(dir / name);
    ASSERT_TRUE(reader->info().crs.has_value());
    EXPECT_EQ(reader->info().crs->wkt, kUtm12Wkt);
    EXPECT_EQ(reader->info().crs->source, "EVLR LASF_Projection 2112 (OGC WKT)");
    EXPECT_TRUE(reader->info().notes.empty());
    const PointCloud points = test::readInBatches(dir / name, {}, nullptr, 2);
    ASSERT_EQ(points.size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(points.positions[i], expectedPosition(spec, spec.points[i]));
      EXPECT_FLOAT_EQ(points.colors[i].g, linearOf16(spec.points[i].green));
    }
  }
  // A WKT in a VLR comes first: the EVLRs are not read.
  spec.vlrs = {test::lasWktRecord("GEOGCS[\"first\"]")};
  test::writeFile(dir / "v.las", makeLas(spec).bytes());
  EXPECT_EQ(openPointFile(dir / "v.las")->info().crs->wkt, "GEOGCS[\"first\"]");
}

// Records that do not fit where the header says are ignored with a note; the points are read.
TEST(LasReader, brokenVariableLengthRecordsAreIgnoredWithANote) {
  constexpr size_t kVlrCountAt = 100, kEvlrStartAt = 235, kEvlrCountAt = 243;
  LasSpec spec{.minor = 4, .format = 6};
  spec.points = samplePoints();
  spec.vlrs = {test::lasWktRecord(kUtm12Wkt)};
  spec.evlrs = {test::lasWktRecord("GEOGCS[\"late\"]")};
  const Bytes valid = makeLas(spec);
  const size_t wktVlrLength = 375 + 20;
  const auto patched = [&](auto change) {
    Bytes file = valid;
    change(file);
    return file;
  };
  struct Case {
    Bytes file;
    std::string note;
    std::string wkt;
  };
  const Case cases[] = {
      {patched([](Bytes& f) { f.patchLE<uint32_t>(kVlrCountAt, 0xFFFFFFFFu); }),
       "announces 4294967295 VLRs but 1 fit before the point data", std::string(kUtm12Wkt)},
      {patched([&](Bytes& f) { f.patchLE<uint16_t>(wktVlrLength, 60000); }),
       "VLR 1 (LASF_Projection 2112) at byte 375 runs past the start of the point data",
       "GEOGCS[\"late\"]"},
      {patched([&](Bytes& f) {
         f.patchLE<uint16_t>(wktVlrLength, 60000);
         f.patchLE<uint64_t>(kEvlrStartAt, 500);
       }),
       "lies inside the point data", ""},
      {patched([&](Bytes& f) {
         f.patchLE<uint16_t>(wktVlrLength, 60000);
         f.patchLE<uint32_t>(kEvlrCountAt, 2);
       }),
       "the file ends at EVLR 2 of 2", "GEOGCS[\"late\"]"},
      {patched([&](Bytes& f) {
         f.patchLE<uint16_t>(wktVlrLength, 60000);
         f.patchLE<uint64_t>(f.size() - std::string_view("GEOGCS[\"late\"]").size() - 1 - 60 + 20,
                             uint64_t{1} << 40);
       }),
       "holds 1099511627776 bytes, more than a coordinate system takes", ""},
  };
  test::TempDir dir;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.note);
    test::writeFile(dir / "b.las", c.file.bytes());
    const auto reader = openPointFile(dir / "b.las");
    std::string notes;
    for (const std::string& note : reader->info().notes) notes += note + "\n";
    EXPECT_NE(notes.find(c.note), std::string::npos) << notes;
    EXPECT_EQ(reader->info().crs ? reader->info().crs->wkt : "", c.wkt);
    const PointCloud points = readPointFile(dir / "b.las");
    ASSERT_EQ(points.size(), 3u);
    EXPECT_EQ(points.positions[1], expectedPosition(spec, spec.points[1]));
  }
}

TEST(LasReader, coordinateSystemTextIsUtf8WithOtherBytesReplaced) {
  LasSpec spec{.format = 0};
  spec.points = samplePoints();
  // "Réseau" in UTF-8, then Latin-1 é, an overlong '/', a lone continuation byte and a cut-off
  // sequence at the end.
  LasRecord wkt = test::lasWktRecord("");
  wkt.payload = Bytes()
                    .text("GEOGCS[\"R\xC3\xA9seau \xE9 \xC0\xAF \x80\"] \xE2\x82")
                    .fill(1, 0)
                    .text("after the NUL")
                    .bytes();
  spec.vlrs = {wkt};
  test::TempDir dir;
  test::writeFile(dir / "u.las", makeLas(spec).bytes());
  const auto reader = openPointFile(dir / "u.las");
  ASSERT_TRUE(reader->info().crs.has_value());
  EXPECT_EQ(reader->info().crs->wkt, "GEOGCS[\"R\xC3\xA9seau ? ?? ?\"] ??");
  EXPECT_EQ(reader->info().crs->name, "R\xC3\xA9seau ? ?? ?");
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

TEST(LasReader, compressedPointFormatsGoToTheLazReader) {
  // A LAS file whose format byte says LASzip (bit 7, or bit 6 of early versions) is read as LAZ,
  // which needs the LASzip VLR that this file lacks.
  LasSpec spec{.format = 3};
  spec.points = samplePoints();
  for (uint8_t bit : {uint8_t{0x80}, uint8_t{0x40}}) {
    Bytes file = makeLas(spec);
    file.patchLE<uint8_t>(kPointFormatAt, uint8_t(3 | bit));
    const std::string error = lasError(file, "c.las");
    EXPECT_TRUE(error.find("no LASzip VLR") != std::string::npos ||
                error.find("no LAZ decoder") != std::string::npos)
        << error;
  }
  EXPECT_NE(lasError(Bytes().text("not las at all"), "b.laz").find("not a LAZ file: no LASF"),
            std::string::npos);
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
