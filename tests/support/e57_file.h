// E57 files built byte by byte from ASTM E2807-11, written here independently of the reader: the
// 48-byte file header (section 8.2, Table 1), pages of pageSize - 4 data bytes followed by their
// CRC-32C in big-endian order (8.2.2), CompressedVector binary sections (9.9.3, Tables 27–31) of
// data, empty and index packets whose bytestreams are packed by the bitpack codec (9.9.3.3), and
// the XML section (8.4) with a point cloud per data3D child, its pose and its prototype.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace iso::test {

// CRC-32C (Castagnoli: reflected polynomial 0x82F63B78, initial value and final XOR all ones),
// byte-wise with a table, as RFC 3720 B.4 defines it.
inline uint32_t crc32c(const std::byte* data, size_t size) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int bit = 0; bit < 8; ++bit) c = (c & 1u) != 0 ? (c >> 1) ^ 0x82F63B78u : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  uint32_t crc = 0xFFFFFFFFu;
  for (size_t i = 0; i < size; ++i) crc = table[(crc ^ uint32_t(data[i])) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

// The E57 point field encodings (E2807 Tables 15–19).
enum class E57Type { kSingle, kDouble, kInteger, kScaledInteger };

struct E57FieldSpec {
  std::string name{};
  E57Type type = E57Type::kDouble;
  int64_t minimum = 0;  // integer types: the bounds written and used for packing
  int64_t maximum = 0;
  double scale = 1.0;  // scaled integers
  double offset = 0.0;
  std::vector<double> floats{};     // kSingle, kDouble: the values
  std::vector<int64_t> integers{};  // kInteger, kScaledInteger: the raw (stored) values
  std::string attributes{};         // further XML attributes, e.g. ` minimum="0" maximum="1"`

  bool isFloat() const { return type == E57Type::kSingle || type == E57Type::kDouble; }
  size_t count() const { return isFloat() ? floats.size() : integers.size(); }
  // Bits per value: 32 or 64 for floats, the bits of maximum - minimum for integers.
  uint32_t bits() const {
    if (type == E57Type::kSingle) return 32;
    if (type == E57Type::kDouble) return 64;
    uint64_t range = uint64_t(maximum) - uint64_t(minimum);
    uint32_t bits = 0;
    for (; range != 0; range >>= 1) ++bits;
    return bits;
  }
};

struct E57ScanSpec {
  std::string name{};
  std::optional<std::array<double, 4>> rotation{};  // quaternion w, x, y, z
  std::optional<std::array<double, 3>> translation{};
  std::string xml{};  // further elements inside the data3D child (colorLimits, ...)
  std::vector<E57FieldSpec> fields{};
  std::optional<uint64_t> recordCount{};  // declared; default: the fields' value count
  size_t recordsPerPacket = 0;            // 0: as many as a 64 KiB packet holds
  // An empty packet after every data packet, and an index packet after the first one's.
  bool emptyAndIndexPackets = false;
  std::string codecs{};  // elements inside <codecs>
};

struct E57Spec {
  uint64_t pageSize = 1024;
  uint32_t versionMajor = 1;
  uint32_t versionMinor = 0;
  std::vector<E57ScanSpec> scans{};
  std::string prolog{};              // between the XML declaration and e57Root (a DOCTYPE)
  std::optional<std::string> xml{};  // the XML section's whole text instead of the generated one
};

// A file before it is cut into pages: the logical byte stream (header first; its offsets are
// physical, as the standard has them) and where its parts lie in it.
struct E57Layout {
  uint64_t pageSize = 1024;
  std::vector<std::byte> logical{};
  std::string xml{};
  uint64_t xmlAt = 0;                                  // logical offset of the XML section
  std::vector<uint64_t> sectionAt{};                   // per scan (0 for scans without values)
  std::vector<std::vector<uint64_t>> dataPacketsAt{};  // per scan, in order

  uint64_t physical(uint64_t logical) const {
    const uint64_t data = pageSize - 4;
    return logical / data * pageSize + logical % data;
  }
};

namespace e57 {

inline void putLE(std::vector<std::byte>& out, uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(std::byte((value >> (8 * i)) & 0xFFu));
}

inline void patchLE(std::vector<std::byte>& out, size_t at, uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out[at + size_t(i)] = std::byte((value >> (8 * i)) & 0xFFu);
}

inline std::string number(double value) {
  char text[64];
  const auto result = std::to_chars(text, text + sizeof text, value);
  return std::string(text, result.ptr);
}

// A field's whole bytestream: values one after another, least significant bit first.
inline std::vector<std::byte> bitpack(const E57FieldSpec& field) {
  std::vector<std::byte> out;
  if (field.type == E57Type::kSingle) {
    for (double v : field.floats) putLE(out, std::bit_cast<uint32_t>(float(v)), 4);
    return out;
  }
  if (field.type == E57Type::kDouble) {
    for (double v : field.floats) putLE(out, std::bit_cast<uint64_t>(v), 8);
    return out;
  }
  // Each value's bits go to the bytes they fall in, a byte's worth (or what is left) at a time.
  const uint32_t bits = field.bits();
  uint64_t position = 0;
  out.assign((field.integers.size() * bits + 7) / 8, std::byte{0});
  for (int64_t value : field.integers) {
    const uint64_t raw = uint64_t(value) - uint64_t(field.minimum);
    for (uint32_t done = 0; done < bits;) {
      const uint32_t shift = uint32_t(position % 8);
      const uint32_t take = std::min(8 - shift, bits - done);
      const uint64_t part = (raw >> done) & ((1u << take) - 1);
      out[position / 8] |= std::byte(part << shift);
      done += take;
      position += take;
    }
  }
  return out;
}

// The most records per data packet that keep it within 64 KiB.
inline size_t recordsPerPacket(const E57ScanSpec& scan) {
  uint64_t bits = 0;
  for (const E57FieldSpec& f : scan.fields) bits += f.bits();
  const uint64_t room =
      65532 - 6 - 2 * scan.fields.size() - scan.fields.size();  // 1 byte slack each
  return bits == 0 ? 1 : size_t(room * 8 / bits);
}

inline void pad4(std::vector<std::byte>& out) {
  while (out.size() % 4 != 0) out.push_back(std::byte{0});
}

// Append a scan's CompressedVector section at the end of `out` (4-byte aligned); returns where it
// starts and, in packetsAt, where its data packets start.
inline uint64_t appendSection(const E57Layout& layout, const E57ScanSpec& scan,
                              std::vector<std::byte>& out, std::vector<uint64_t>& packetsAt) {
  pad4(out);
  const uint64_t start = out.size();
  size_t records = 0;
  std::vector<std::vector<std::byte>> streams;
  for (const E57FieldSpec& f : scan.fields) {
    records = std::max(records, f.count());
    streams.push_back(bitpack(f));
  }
  out.push_back(std::byte{1});  // sectionId: CompressedVector
  out.insert(out.end(), 7, std::byte{0});
  putLE(out, 0, 8);  // sectionLogicalLength, patched below
  putLE(out, 0, 8);  // dataPhysicalOffset, patched below
  putLE(out, 0, 8);  // indexPhysicalOffset, patched below (0: none)
  const size_t perPacket =
      scan.recordsPerPacket != 0 ? scan.recordsPerPacket : recordsPerPacket(scan);
  const auto cut = [&](size_t field, size_t record) {
    return std::min(streams[field].size(), (record * scan.fields[field].bits() + 7) / 8);
  };
  patchLE(out, start + 16, layout.physical(start + 32), 8);
  for (size_t first = 0; first < records; first += perPacket) {
    const size_t last = std::min(records, first + perPacket);
    const size_t at = out.size();
    packetsAt.push_back(at);
    out.push_back(std::byte{1});  // data packet
    out.push_back(std::byte{0});  // flags
    putLE(out, 0, 2);             // length - 1, patched below
    putLE(out, scan.fields.size(), 2);
    for (size_t f = 0; f < scan.fields.size(); ++f) putLE(out, cut(f, last) - cut(f, first), 2);
    for (size_t f = 0; f < scan.fields.size(); ++f)
      out.insert(out.end(), streams[f].begin() + ptrdiff_t(cut(f, first)),
                 streams[f].begin() + ptrdiff_t(cut(f, last)));
    pad4(out);
    // A packet holds at most 64 KiB (its length is a 16-bit count): recordsPerPacket keeps it so.
    if (out.size() - at > 65536) throw std::logic_error("an E57 data packet over 64 KiB");
    patchLE(out, at + 2, out.size() - at - 1, 2);
    if (!scan.emptyAndIndexPackets) continue;
    out.push_back(std::byte{2});  // empty packet: type, reserved, length - 1, padding
    out.push_back(std::byte{0});
    putLE(out, 8 - 1, 2);
    putLE(out, 0, 4);
    if (first != 0) continue;
    // Index packet (Table 29): type, reserved, length - 1, entryCount, indexLevel, 9 reserved
    // bytes, then entries of a record number and a data packet's physical offset.
    patchLE(out, start + 24, layout.physical(out.size()), 8);
    out.push_back(std::byte{0});
    out.push_back(std::byte{0});
    putLE(out, 32 - 1, 2);
    putLE(out, 1, 2);
    out.push_back(std::byte{0});
    out.insert(out.end(), 9, std::byte{0});
    putLE(out, 0, 8);
    putLE(out, layout.physical(at), 8);
  }
  patchLE(out, start + 8, out.size() - start, 8);
  return start;
}

inline std::string fieldXml(const E57FieldSpec& f) {
  std::string xml = "<" + f.name;
  switch (f.type) {
    case E57Type::kSingle:
      xml += " type=\"Float\" precision=\"single\"";
      break;
    case E57Type::kDouble:
      xml += " type=\"Float\"";
      break;
    case E57Type::kInteger:
      xml += " type=\"Integer\" minimum=\"" + std::to_string(f.minimum) + "\" maximum=\"" +
             std::to_string(f.maximum) + "\"";
      break;
    case E57Type::kScaledInteger:
      xml += " type=\"ScaledInteger\" minimum=\"" + std::to_string(f.minimum) + "\" maximum=\"" +
             std::to_string(f.maximum) + "\" scale=\"" + number(f.scale) + "\" offset=\"" +
             number(f.offset) + "\"";
      break;
  }
  return xml + f.attributes + "/>\n";
}

inline std::string scanXml(const E57ScanSpec& scan, size_t index, uint64_t fileOffset) {
  std::string xml = "<vectorChild type=\"Structure\">\n";
  xml += "<guid type=\"String\"><![CDATA[{iso-test-scan-" + std::to_string(index) + "}]]></guid>\n";
  if (!scan.name.empty()) xml += "<name type=\"String\"><![CDATA[" + scan.name + "]]></name>\n";
  if (scan.rotation || scan.translation) {
    xml += "<pose type=\"Structure\">\n";
    if (scan.rotation) {
      xml += "<rotation type=\"Structure\">";
      const char* names[] = {"w", "x", "y", "z"};
      for (int i = 0; i < 4; ++i)
        xml += std::string("<") + names[i] + " type=\"Float\">" +
               number((*scan.rotation)[size_t(i)]) + "</" + names[i] + ">";
      xml += "</rotation>\n";
    }
    if (scan.translation) {
      xml += "<translation type=\"Structure\">";
      const char* names[] = {"x", "y", "z"};
      for (int i = 0; i < 3; ++i)
        xml += std::string("<") + names[i] + " type=\"Float\">" +
               number((*scan.translation)[size_t(i)]) + "</" + names[i] + ">";
      xml += "</translation>\n";
    }
    xml += "</pose>\n";
  }
  xml += scan.xml;
  size_t records = 0;
  for (const E57FieldSpec& f : scan.fields) records = std::max(records, f.count());
  xml += "<points type=\"CompressedVector\" fileOffset=\"" + std::to_string(fileOffset) +
         "\" recordCount=\"" + std::to_string(scan.recordCount.value_or(records)) + "\">\n";
  xml += "<prototype type=\"Structure\">\n";
  for (const E57FieldSpec& f : scan.fields) xml += fieldXml(f);
  xml += "</prototype>\n<codecs type=\"Vector\" allowHeterogeneousChildren=\"1\">" + scan.codecs +
         "</codecs>\n</points>\n</vectorChild>\n";
  return xml;
}

}  // namespace e57

// Lay a file out: header, a section per scan with values, the XML section last.
inline E57Layout layoutE57(const E57Spec& spec) {
  E57Layout layout;
  layout.pageSize = spec.pageSize;
  std::vector<std::byte>& out = layout.logical;
  out.resize(48);
  std::string data3D;
  for (size_t i = 0; i < spec.scans.size(); ++i) {
    const E57ScanSpec& scan = spec.scans[i];
    size_t records = 0;
    for (const E57FieldSpec& f : scan.fields) records = std::max(records, f.count());
    layout.dataPacketsAt.emplace_back();
    layout.sectionAt.push_back(
        records == 0 ? 0 : e57::appendSection(layout, scan, out, layout.dataPacketsAt.back()));
    // libE57Format's old habit for empty scans: fileOffset 0.
    data3D += e57::scanXml(scan, i, records == 0 ? 0 : layout.physical(layout.sectionAt.back()));
  }
  layout.xml = spec.xml.value_or(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n" + spec.prolog +
      "<e57Root type=\"Structure\" xmlns=\"http://www.astm.org/COMMIT/E57/2010-e57-v1.0\">\n"
      "<formatName type=\"String\"><![CDATA[ASTM E57 3D Imaging Data File]]></formatName>\n"
      "<guid type=\"String\"><![CDATA[{iso-test-file}]]></guid>\n"
      "<versionMajor type=\"Integer\">1</versionMajor>\n"
      "<versionMinor type=\"Integer\">0</versionMinor>\n"
      "<coordinateMetadata type=\"String\"/>\n"
      "<data3D type=\"Vector\" allowHeterogeneousChildren=\"1\">\n" +
      data3D +
      "</data3D>\n<images2D type=\"Vector\" allowHeterogeneousChildren=\"1\"/>\n</e57Root>\n");
  e57::pad4(out);
  layout.xmlAt = out.size();
  for (char c : layout.xml) out.push_back(std::byte(c));
  const uint64_t data = spec.pageSize - 4;
  const uint64_t pages = (out.size() + data - 1) / data;
  std::vector<std::byte> header;
  for (char c : std::string("ASTM-E57")) header.push_back(std::byte(c));
  e57::putLE(header, spec.versionMajor, 4);
  e57::putLE(header, spec.versionMinor, 4);
  e57::putLE(header, pages * spec.pageSize, 8);  // filePhysicalLength
  e57::putLE(header, layout.physical(layout.xmlAt), 8);
  e57::putLE(header, layout.xml.size(), 8);  // xmlLogicalLength
  e57::putLE(header, spec.pageSize, 8);
  std::copy(header.begin(), header.end(), out.begin());
  return layout;
}

// Cut a logical stream into pages, each with the CRC-32C of its data in big-endian order; the last
// page is filled with zeros.
inline std::vector<std::byte> pageE57(const std::vector<std::byte>& logical, uint64_t pageSize) {
  const size_t data = size_t(pageSize) - 4;
  std::vector<std::byte> out;
  for (size_t at = 0; at < logical.size(); at += data) {
    const size_t page = out.size();
    const size_t take = std::min(data, logical.size() - at);
    out.insert(out.end(), logical.begin() + ptrdiff_t(at), logical.begin() + ptrdiff_t(at + take));
    out.insert(out.end(), data - take, std::byte{0});
    const uint32_t crc = crc32c(out.data() + page, data);
    for (int shift = 24; shift >= 0; shift -= 8) out.push_back(std::byte((crc >> shift) & 0xFFu));
  }
  return out;
}

inline std::vector<std::byte> makeE57(const E57Spec& spec) {
  return pageE57(layoutE57(spec).logical, spec.pageSize);
}

}  // namespace iso::test
