// LAS files built byte by byte from the ASPRS LAS 1.4 specification (R15), written here
// independently of the reader: versions 1.2–1.4, point formats 0–10 with extra bytes, VLRs and
// (LAS 1.4) EVLRs such as the coordinate system's (OGC WKT, GeoTIFF keys) and the Extra Bytes
// description.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "tests/io/io_test_util.h"

namespace iso::test {

// Standard record size of each point format and where its RGB starts (0: no RGB), from the spec's
// record tables (sections 2.6–2.16).
inline constexpr uint16_t kLasStandardSize[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
inline constexpr uint16_t kLasRgbOffset[11] = {0, 0, 20, 28, 0, 28, 0, 30, 30, 0, 30};

struct LasPoint {
  int32_t x = 0, y = 0, z = 0;
  uint16_t red = 0, green = 0, blue = 0;
  // Written when `fields` (else the record's other bytes are 0xA5): intensity at 12, the return
  // byte at 14, the classification at 15 (formats 0-5) or 16 (6-10), the GPS time at 20 (1, 3-5)
  // or 22 (6-10) (LAS 1.4 R15, Tables 7-17).
  bool fields = false;
  uint16_t intensity = 0;
  uint8_t returns = 0, classification = 0;
  double gpsTime = 0.0;
};

// A variable length record: in the VLRs (54-byte header) or EVLRs (60-byte header).
struct LasRecord {
  std::string user;
  uint16_t id = 0;
  std::vector<std::byte> payload;
};

struct LasSpec {
  int minor = 2;
  int format = 0;
  int extraBytes = 0;  // bytes after the standard record, filled with 0xEE
  glm::dvec3 scale{0.01};
  glm::dvec3 offset{0.0};
  std::vector<LasPoint> points{};
  int vlrPayload = -1;  // bytes of a VLR LASF_Projection 34735 of 0x55 bytes; negative: none
  std::vector<LasRecord> vlrs{};
  std::vector<LasRecord> evlrs{};  // LAS 1.4: after the point data
};

inline size_t lasHeaderSize(int minor) { return minor >= 4 ? 375 : minor == 3 ? 235 : 227; }

inline void appendLasRecord(Bytes& b, const LasRecord& r, bool isExtended) {
  b.le<uint16_t>(0).text(r.user).fill(16 - r.user.size(), 0).le(r.id);
  if (isExtended) {
    b.le(uint64_t(r.payload.size()));
  } else {
    b.le(uint16_t(r.payload.size()));
  }
  b.text("iso test record").fill(17, 0);
  for (std::byte x : r.payload) b.le(x);
}

inline Bytes makeLas(const LasSpec& s) {
  const size_t headerSize = lasHeaderSize(s.minor);
  const size_t recordLength = kLasStandardSize[s.format] + size_t(s.extraBytes);
  std::vector<LasRecord> vlrs = s.vlrs;
  if (s.vlrPayload >= 0)
    vlrs.push_back(
        {"LASF_Projection", 34735, std::vector<std::byte>(size_t(s.vlrPayload), std::byte{0x55})});
  size_t vlrBytes = 0;
  for (const LasRecord& r : vlrs) vlrBytes += 54 + r.payload.size();
  const uint64_t count = s.points.size();
  const uint64_t evlrStart = s.evlrs.empty() ? 0 : headerSize + vlrBytes + count * recordLength;
  Bytes b;
  b.text("LASF").le<uint16_t>(7).le<uint16_t>(0).fill(16, 0).le<uint8_t>(1).le(uint8_t(s.minor));
  b.text("iso test").fill(24, 0).text("las_reader_test").fill(17, 0);
  b.le<uint16_t>(1).le<uint16_t>(2024).le(uint16_t(headerSize)).le(uint32_t(headerSize + vlrBytes));
  b.le(uint32_t(vlrs.size())).le(uint8_t(s.format)).le(uint16_t(recordLength));
  b.le(uint32_t(s.format < 6 ? count : 0)).fill(20, 0);
  for (int axis = 0; axis < 3; ++axis) b.le(s.scale[axis]);
  for (int axis = 0; axis < 3; ++axis) b.le(s.offset[axis]);
  b.fill(48, 0);  // bounds
  if (s.minor >= 3) b.le<uint64_t>(0);
  if (s.minor >= 4) b.le(evlrStart).le(uint32_t(s.evlrs.size())).le(count).fill(15 * 8, 0);
  EXPECT_EQ(b.size(), headerSize);
  for (const LasRecord& r : vlrs) appendLasRecord(b, r, false);
  for (const LasPoint& p : s.points) {
    const size_t at = b.size();
    b.le(p.x).le(p.y).le(p.z).fill(kLasStandardSize[s.format] - 12, 0xA5);
    const size_t rgb = kLasRgbOffset[s.format];
    if (rgb != 0) {
      b.patchLE(at + rgb, p.red);
      b.patchLE(at + rgb + 2, p.green);
      b.patchLE(at + rgb + 4, p.blue);
    }
    if (p.fields) {
      const bool extended = s.format >= 6;
      b.patchLE(at + 12, p.intensity);
      b.patchLE(at + 14, p.returns);
      b.patchLE(at + (extended ? 16 : 15), p.classification);
      if (s.format != 0 && s.format != 2) b.patchLE(at + (extended ? 22 : 20), p.gpsTime);
    }
    b.fill(size_t(s.extraBytes), 0xEE);
  }
  EXPECT_TRUE(s.evlrs.empty() || b.size() == evlrStart);
  for (const LasRecord& r : s.evlrs) appendLasRecord(b, r, true);
  return b;
}

// The OGC WKT record (LASF_Projection 2112): the text and its terminating NUL.
inline LasRecord lasWktRecord(std::string_view wkt) {
  LasRecord r{"LASF_Projection", 2112, {}};
  for (char c : wkt) r.payload.push_back(std::byte(c));
  r.payload.push_back(std::byte{0});
  return r;
}

// The GeoTIFF key directory (LASF_Projection 34735): version 1, revision 1.0, then the keys, four
// shorts each (id, location, count, value or offset).
inline LasRecord lasGeoKeysRecord(const std::vector<std::array<uint16_t, 4>>& keys) {
  Bytes b;
  b.le<uint16_t>(1).le<uint16_t>(1).le<uint16_t>(0).le(uint16_t(keys.size()));
  for (const auto& key : keys)
    for (uint16_t value : key) b.le(value);
  return {"LASF_Projection", 34735, b.bytes()};
}

// The GeoTIFF ASCII parameters (LASF_Projection 34737), '|'-terminated strings one after another.
inline LasRecord lasGeoAsciiRecord(std::string_view text) {
  return {"LASF_Projection", 34737, Bytes().text(text).bytes()};
}

// The Extra Bytes description (LASF_Spec 4): 192 bytes per field (LAS 1.4 Table 24) with its data
// type (1–10: u8 i8 u16 i16 u32 i32 u64 i64 f32 f64) and name.
inline LasRecord lasExtraBytesRecord(const std::vector<std::pair<uint8_t, std::string>>& fields) {
  Bytes b;
  for (const auto& [type, name] : fields) {
    b.fill(2, 0).le(type).le<uint8_t>(0).text(name).fill(32 - name.size(), 0);
    b.fill(4 + 3 * 24, 0);                  // unused, no_data, min, max
    for (int i = 0; i < 3; ++i) b.le(1.0);  // scale
    for (int i = 0; i < 3; ++i) b.le(0.0);  // offset
    b.text("iso test field").fill(18, 0);   // description
  }
  return {"LASF_Spec", 4, b.bytes()};
}

}  // namespace iso::test
