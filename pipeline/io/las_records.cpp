#include "pipeline/io/las_records.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cstring>

#include "pipeline/io/little_endian.h"
#include "pipeline/io/text_fields.h"

namespace iso::io {
namespace {

// Record headers (LAS 1.4 Tables 15 and 21): reserved u16, user id char[16], record id u16, the
// payload's length (u16 in a VLR, u64 in an EVLR), description char[32].
constexpr size_t kVlrHeaderBytes = 54;
constexpr size_t kEvlrHeaderBytes = 60;
constexpr size_t kUserIdAt = 2;
constexpr size_t kUserIdBytes = 16;
constexpr size_t kRecordIdAt = 18;
constexpr size_t kLengthAt = 20;

constexpr std::string_view kProjectionUser = "LASF_Projection";
constexpr uint16_t kWktRecord = 2112;
constexpr uint16_t kGeoKeyDirectoryRecord = 34735;
constexpr uint16_t kGeoAsciiParamsRecord = 34737;

// An EVLR's WKT larger than this is not a coordinate system: it is skipped.
constexpr uint64_t kMaxEvlrPayload = uint64_t{1} << 20;

// GeoTIFF keys (GeoTIFF 1.0 §6.2) and the codes that name no EPSG entry.
constexpr uint16_t kGtCitationKey = 1026;
constexpr uint16_t kGeographicTypeKey = 2048;
constexpr uint16_t kProjectedTypeKey = 3072;
constexpr uint16_t kPcsCitationKey = 3073;
constexpr uint16_t kVerticalTypeKey = 4096;
constexpr uint16_t kUserDefined = 32767;

std::string userIdOf(const std::byte* header) {
  const auto* text = reinterpret_cast<const char*>(header + kUserIdAt);
  return std::string(text, strnlen(text, kUserIdBytes));
}

// The length of the well-formed UTF-8 sequence at text[i] (RFC 3629), 0 when it is not one.
size_t utf8Length(std::string_view text, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<uint8_t>(text[i + k]); };
  const uint8_t lead = byte(0);
  if (lead < 0x80) return 1;
  size_t length = 0;
  uint8_t low = 0x80, high = 0xBF;  // the range of the second byte
  if (lead >= 0xC2 && lead <= 0xDF) {
    length = 2;
  } else if (lead >= 0xE0 && lead <= 0xEF) {
    length = 3;
    if (lead == 0xE0) low = 0xA0;   // no overlong forms
    if (lead == 0xED) high = 0x9F;  // no surrogates
  } else if (lead >= 0xF0 && lead <= 0xF4) {
    length = 4;
    if (lead == 0xF0) low = 0x90;
    if (lead == 0xF4) high = 0x8F;  // nothing past U+10FFFF
  }
  if (length == 0 || i + length > text.size() || byte(1) < low || byte(1) > high) return 0;
  for (size_t k = 2; k < length; ++k)
    if ((byte(k) & 0xC0) != 0x80) return 0;
  return length;
}

// Text from a record: up to its first NUL, without trailing blanks and GeoTIFF's '|' terminator,
// as UTF-8 (bytes that are not become '?').
std::string recordText(std::string_view bytes) {
  bytes = bytes.substr(0, bytes.find('\0'));
  while (!bytes.empty() &&
         (bytes.back() == '|' || std::isspace(static_cast<unsigned char>(bytes.back()))))
    bytes.remove_suffix(1);
  std::string text;
  text.reserve(bytes.size());
  for (size_t i = 0; i < bytes.size();) {
    const size_t length = utf8Length(bytes, i);
    text.append(length == 0 ? std::string_view("?") : bytes.substr(i, length));
    i += std::max<size_t>(length, 1);
  }
  return text;
}

// The first quoted name of a WKT ("PROJCS["NAD83 / UTM zone 12N", ...").
std::string wktName(const std::string& wkt) {
  const size_t open = wkt.find('"');
  if (open == std::string::npos) return "";
  const size_t close = wkt.find('"', open + 1);
  return close == std::string::npos ? "" : wkt.substr(open + 1, close - open - 1);
}

// The EPSG code of the authority element of a WKT's root ("...,AUTHORITY["EPSG","32612"]]" in
// WKT 1, "...,ID["EPSG",32612]]" in WKT 2); nested elements' authorities are not the system's.
std::optional<uint32_t> wktEpsg(const std::string& wkt) {
  int depth = 0;
  bool isQuoted = false;
  for (size_t i = 0; i < wkt.size(); ++i) {
    const char c = wkt[i];
    if (c == '"') isQuoted = !isQuoted;
    if (isQuoted || (c != '[' && c != ']')) continue;
    depth += c == '[' ? 1 : -1;
    if (c != '[' || depth != 2) continue;
    size_t start = i;
    while (start > 0 && std::isalpha(static_cast<unsigned char>(wkt[start - 1]))) --start;
    const std::string keyword = wkt.substr(start, i - start);
    if (keyword != "AUTHORITY" && keyword != "ID") continue;
    std::string_view content = std::string_view(wkt).substr(i + 1);
    content = content.substr(0, content.find(']'));
    if (!content.starts_with("\"EPSG\",")) continue;
    content.remove_prefix(7);
    if (content.starts_with('"')) content = content.substr(1, content.find('"', 1) - 1);
    int64_t code = 0;
    if (parseInteger(content, code) && code > 0 && code < kUserDefined) return uint32_t(code);
  }
  return std::nullopt;
}

std::optional<uint32_t> epsgCode(std::optional<uint16_t> value) {
  if (!value || *value == 0 || *value >= kUserDefined) return std::nullopt;
  return *value;
}

struct GeoKeyValues {
  std::optional<uint16_t> projected, geographic, vertical;
  std::string pcsCitation, gtCitation;
};

// The values of the keys the reader uses: short values in the directory, citations in the ASCII
// parameters.
GeoKeyValues readGeoKeys(const std::vector<uint16_t>& keys, size_t count, const std::string& ascii,
                         std::vector<std::string>& notes) {
  GeoKeyValues values;
  for (size_t k = 0; k < count; ++k) {
    const uint16_t* entry = keys.data() + 4 + 4 * k;  // id, location, count, value or offset
    const uint16_t id = entry[0], location = entry[1], length = entry[2], value = entry[3];
    if (location == 0) {
      if (id == kProjectedTypeKey) values.projected = value;
      if (id == kGeographicTypeKey) values.geographic = value;
      if (id == kVerticalTypeKey) values.vertical = value;
    } else if (location == kGeoAsciiParamsRecord &&
               (id == kPcsCitationKey || id == kGtCitationKey)) {
      if (size_t{value} + length > ascii.size()) {
        notes.push_back(
            fmt::format("GeoTIFF key {} refers to ASCII parameters the file does not "
                        "hold (LASF_Projection {}): ignored",
                        id, kGeoAsciiParamsRecord));
        continue;
      }
      (id == kPcsCitationKey ? values.pcsCitation : values.gtCitation) =
          recordText(std::string_view(ascii).substr(value, length));
    }
  }
  return values;
}

// Fill crs from the GeoTIFF key directory (GeoTIFF 1.0 §2.4: a header of version 1, revision,
// minor revision and the number of keys, then four shorts per key).
void decodeGeoKeys(const std::vector<uint16_t>& keys, const std::string& ascii,
                   CoordinateSystem& crs, std::vector<std::string>& notes) {
  if (keys.size() < 4 || keys[0] != 1) {
    notes.push_back(
        fmt::format("the GeoTIFF key directory (LASF_Projection {}) is not one of "
                    "version 1: ignored",
                    kGeoKeyDirectoryRecord));
    return;
  }
  size_t count = keys[3];
  if (4 + 4 * count > keys.size()) {
    notes.push_back(
        fmt::format("the GeoTIFF key directory (LASF_Projection {}) announces {} keys "
                    "but holds {}: those are read",
                    kGeoKeyDirectoryRecord, count, (keys.size() - 4) / 4));
    count = (keys.size() - 4) / 4;
  }
  const GeoKeyValues values = readGeoKeys(keys, count, ascii, notes);
  crs.epsg = epsgCode(values.projected);
  if (!crs.epsg) crs.epsg = epsgCode(values.geographic);
  crs.verticalEpsg = epsgCode(values.vertical);
  crs.name = !values.pcsCitation.empty() ? values.pcsCitation : values.gtCitation;
}

std::string describe(std::string_view where, uint16_t recordId) {
  const char* what = recordId == kWktRecord               ? "OGC WKT"
                     : recordId == kGeoKeyDirectoryRecord ? "GeoTIFF keys"
                                                          : "GeoTIFF ASCII parameters";
  return fmt::format("{} {} {} ({})", where, kProjectionUser, recordId, what);
}

}  // namespace

bool LasCoordinateRecords::isWanted(std::string_view userId, uint16_t recordId) {
  return userId == kProjectionUser &&
         (recordId == kWktRecord || recordId == kGeoKeyDirectoryRecord ||
          recordId == kGeoAsciiParamsRecord);
}

void LasCoordinateRecords::add(uint16_t recordId, std::span<const std::byte> payload,
                               std::string_view where) {
  const std::string_view bytes(reinterpret_cast<const char*>(payload.data()), payload.size());
  if (recordId == kWktRecord && wkt_.empty()) {
    wkt_ = recordText(bytes);
    if (!wkt_.empty()) sources_.push_back(describe(where, recordId));
  } else if (recordId == kGeoKeyDirectoryRecord && geoKeys_.empty()) {
    for (size_t at = 0; at + 2 <= payload.size(); at += 2)
      geoKeys_.push_back(loadLittleEndian<uint16_t>(payload.data() + at));
    sources_.push_back(describe(where, recordId));
  } else if (recordId == kGeoAsciiParamsRecord && geoAscii_.empty()) {
    geoAscii_.assign(bytes);  // split by the keys' offsets, so kept whole
  }
}

std::optional<CoordinateSystem> LasCoordinateRecords::coordinateSystem(
    std::vector<std::string>& notes) const {
  CoordinateSystem crs;
  crs.wkt = wkt_;
  if (!geoKeys_.empty()) decodeGeoKeys(geoKeys_, geoAscii_, crs, notes);
  if (crs.wkt.empty() && !crs.epsg && !crs.verticalEpsg) {
    if (!geoKeys_.empty())
      notes.push_back(
          "the GeoTIFF keys name no EPSG code (user-defined) and there is no WKT: "
          "no coordinate system is kept");
    return std::nullopt;
  }
  if (crs.name.empty()) crs.name = wktName(crs.wkt);
  if (!crs.epsg) crs.epsg = wktEpsg(crs.wkt);
  for (const std::string& source : sources_)
    crs.source += (crs.source.empty() ? "" : ", ") + source;
  return crs;
}

void readLasVlrs(InputStream& in, uint64_t pointDataOffset, uint32_t count,
                 LasCoordinateRecords& records, std::vector<std::string>& notes,
                 std::vector<std::byte>* laszip) {
  for (uint32_t i = 0; i < count; ++i) {
    const uint64_t at = in.offset();
    if (at + kVlrHeaderBytes > pointDataOffset) {
      notes.push_back(
          fmt::format("the header announces {} VLRs but {} fit before the point data "
                      "at byte {}: the others are ignored",
                      count, i, pointDataOffset));
      break;
    }
    const std::span<const std::byte> header = in.peek(kVlrHeaderBytes);
    if (header.size() < kVlrHeaderBytes)
      in.fail(fmt::format("file ends inside VLR {} of {}", i + 1, count));
    const std::string user = userIdOf(header.data());
    const uint16_t id = loadLittleEndian<uint16_t>(header.data() + kRecordIdAt);
    const uint64_t length = loadLittleEndian<uint16_t>(header.data() + kLengthAt);
    if (at + kVlrHeaderBytes + length > pointDataOffset) {
      notes.push_back(
          fmt::format("VLR {} ({} {}) at byte {} runs past the start of the point "
                      "data at byte {}: it and those after it are ignored",
                      i + 1, user, id, at, pointDataOffset));
      break;
    }
    in.consume(kVlrHeaderBytes);
    const std::span<const std::byte> payload = in.peek(length);
    if (payload.size() < length)
      in.fail(fmt::format("file ends inside VLR {} of {}", i + 1, count));
    if (LasCoordinateRecords::isWanted(user, id)) records.add(id, payload.first(length), "VLR");
    if (laszip != nullptr && user == kLaszipUser && id == kLaszipRecord && laszip->empty())
      laszip->assign(payload.begin(), payload.begin() + ptrdiff_t(length));
    in.consume(length);
  }
}

void readLasEvlrs(const std::filesystem::path& path, uint64_t start, uint32_t count,
                  uint64_t pointDataEnd, LasCoordinateRecords& records,
                  std::vector<std::string>& notes) {
  if (count == 0) return;
  if (start < pointDataEnd) {
    notes.push_back(
        fmt::format("the EVLRs' start, byte {}, lies inside the point data (which "
                    "ends at byte {}): they are ignored",
                    start, pointDataEnd));
    return;
  }
  InputStream in(path);
  in.seek(start);
  for (uint32_t i = 0; i < count; ++i) {
    const std::span<const std::byte> header = in.peek(kEvlrHeaderBytes);
    if (header.size() < kEvlrHeaderBytes) {
      notes.push_back(
          fmt::format("the file ends at EVLR {} of {} (byte {}): the others are "
                      "ignored",
                      i + 1, count, in.offset()));
      return;
    }
    const std::string user = userIdOf(header.data());
    const uint16_t id = loadLittleEndian<uint16_t>(header.data() + kRecordIdAt);
    const uint64_t length = loadLittleEndian<uint64_t>(header.data() + kLengthAt);
    in.consume(kEvlrHeaderBytes);
    const uint64_t next = in.offset() + length;
    if (LasCoordinateRecords::isWanted(user, id) && length <= kMaxEvlrPayload) {
      const std::span<const std::byte> payload = in.peek(length);
      if (payload.size() < length) {
        notes.push_back(
            fmt::format("the file ends inside EVLR {} ({} {}): it is ignored", i + 1, user, id));
        return;
      }
      records.add(id, payload.first(length), "EVLR");
    } else if (LasCoordinateRecords::isWanted(user, id)) {
      notes.push_back(
          fmt::format("EVLR {} ({} {}) holds {} bytes, more than a coordinate system "
                      "takes: it is ignored",
                      i + 1, user, id, length));
    }
    if (i + 1 < count) {
      if (next < in.offset()) return;  // a length that wraps around: nothing follows
      in.seek(next);
    }
  }
}

std::optional<CoordinateSystem> readLasCoordinateSystem(InputStream& in, const LasHeader& header,
                                                        uint64_t pointDataEnd,
                                                        std::vector<std::string>& notes,
                                                        std::vector<std::byte>* laszip) {
  if (in.skip(header.headerSize) != header.headerSize)
    in.fail(fmt::format("file ends inside the {}-byte header", header.headerSize));
  LasCoordinateRecords records;
  readLasVlrs(in, header.pointDataOffset, header.vlrCount, records, notes, laszip);
  if (!records.hasWkt() && header.evlrCount > 0)
    readLasEvlrs(in.path(), header.evlrStart, header.evlrCount, pointDataEnd, records, notes);
  return records.coordinateSystem(notes);
}

}  // namespace iso::io
