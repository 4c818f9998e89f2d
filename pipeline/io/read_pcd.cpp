// The PCD reader: the Point Cloud Library's point file format, version 0.7 (PCL documentation, "The
// PCD (Point Cloud Data) file format"; PCL io/src/pcd_io.cpp for what the documentation leaves
// out). A text header of keyword lines (FIELDS SIZE TYPE COUNT WIDTH HEIGHT VIEWPOINT POINTS DATA)
// is followed by the points: one text line each (DATA ascii), packed little-endian records (DATA
// binary), or one LZF block holding each field's values for all points in turn (DATA
// binary_compressed).
#include <fmt/format.h>
#include <lzf.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include "iso/error.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/little_endian.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/point_readers.h"
#include "pipeline/io/text_fields.h"

namespace iso::io {
namespace {

// Point records above this size are refused: real ones are at most a few KiB (SHOT descriptors),
// and the cap keeps a hostile COUNT from sizing buffers.
constexpr uint64_t kMaxRecordBytes = uint64_t{1} << 20;

// A 3-byte LZF back reference expands to at most 264 bytes (liblzf lzf_d.c), so a block cannot
// decompress to more than 88 times its size: larger claims are refused before allocating.
constexpr uint64_t kMaxLzfExpansion = 88;

// Compressed bytes read at a time, so that a hostile block size in a .gz file (whose length is
// unknown up front) allocates no more than the data that is actually there.
constexpr size_t kCompressedChunkBytes = size_t{16} << 20;

enum class PcdData : uint8_t { kAscii, kBinary, kBinaryCompressed };

enum class ScalarType : uint8_t {
  kInt8,
  kInt16,
  kInt32,
  kInt64,
  kUInt8,
  kUInt16,
  kUInt32,
  kUInt64,
  kFloat32,
  kFloat64
};

// The TYPE letter and SIZE of each scalar type; other combinations (F2, I3, ...) are refused.
struct TypeCode {
  std::string_view letter;
  uint64_t size;
  ScalarType type;
};
constexpr std::array<TypeCode, 10> kTypeCodes = {{{"I", 1, ScalarType::kInt8},
                                                  {"I", 2, ScalarType::kInt16},
                                                  {"I", 4, ScalarType::kInt32},
                                                  {"I", 8, ScalarType::kInt64},
                                                  {"U", 1, ScalarType::kUInt8},
                                                  {"U", 2, ScalarType::kUInt16},
                                                  {"U", 4, ScalarType::kUInt32},
                                                  {"U", 8, ScalarType::kUInt64},
                                                  {"F", 4, ScalarType::kFloat32},
                                                  {"F", 8, ScalarType::kFloat64}}};

// Header keywords; COLUMNS, the v0.5 name of FIELDS, is read as FIELDS.
enum Keyword : uint8_t {
  kVersion,
  kFields,
  kSize,
  kType,
  kCount,
  kWidth,
  kHeight,
  kViewpoint,
  kPoints,
  kData,
  kKeywordCount
};
constexpr std::array<std::string_view, kKeywordCount> kKeywords = {
    "VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};

struct HeaderLine {
  uint64_t number = 0;  // line number in the file; 0: the header has no such line
  std::vector<std::string> values;
};
using HeaderLines = std::array<HeaderLine, kKeywordCount>;

// What the reader takes from the fields. A packed color is PCL's rgb or rgba: one 4-byte value
// (float or integer) whose bits are 0xAARRGGBB.
enum Slot : uint8_t { kX, kY, kZ, kNx, kNy, kNz, kRed, kGreen, kBlue, kPackedColor, kSlotCount };
// Field names of each slot, in the order of Slot; "" pads the shorter lists.
using SlotNames = std::array<std::string_view, 2>;
constexpr std::array<SlotNames, kSlotCount> kSlotNames = {{{"x", ""},
                                                           {"y", ""},
                                                           {"z", ""},
                                                           {"normal_x", "nx"},
                                                           {"normal_y", "ny"},
                                                           {"normal_z", "nz"},
                                                           {"r", "red"},
                                                           {"g", "green"},
                                                           {"b", "blue"},
                                                           {"rgb", "rgba"}}};

struct PcdField {
  std::string name;
  ScalarType type = ScalarType::kFloat32;
  uint64_t size = 4;   // bytes per value
  uint64_t count = 1;  // values per point
};

struct PcdHeader {
  std::vector<PcdField> fields;
  uint64_t points = 0;
  PcdData data = PcdData::kAscii;
  std::array<int, kSlotCount> slotField{};  // the field each slot reads, -1 when none
  bool hasNormals = false;
  bool hasColors = false;
};

[[noreturn]] void failOnLine(const InputStream& in, uint64_t line, const std::string& reason) {
  throw FileError(in.name(), std::nullopt, fmt::format("line {}: {}", line, reason));
}

// Read the keyword lines up to and including DATA, skipping comments (#) and blank lines. Unknown
// keywords are refused, so that a file that is not PCD fails on its first line.
HeaderLines readHeaderLines(InputStream& in) {
  HeaderLines lines;
  std::string_view line;
  while (lines[kData].number == 0) {
    if (!in.readLine(line)) in.fail("file ends in the PCD header, before its DATA line");
    std::string_view keyword;
    if (!nextField<isBlank>(line, keyword) || keyword.starts_with('#')) continue;
    if (keyword == "COLUMNS") keyword = "FIELDS";
    const auto* known = std::find(kKeywords.begin(), kKeywords.end(), keyword);
    if (known == kKeywords.end())
      in.failLine(fmt::format("'{:.40}' is not a PCD header keyword", keyword));
    HeaderLine& entry = lines[static_cast<size_t>(known - kKeywords.begin())];
    if (entry.number != 0) in.failLine(fmt::format("a second {} line", keyword));
    entry.number = in.lineNumber();
    std::string_view value;
    while (nextField<isBlank>(line, value)) entry.values.emplace_back(value);
  }
  return lines;
}

const HeaderLine& requiredLine(const InputStream& in, const HeaderLines& lines, Keyword keyword) {
  if (lines[keyword].number == 0)
    failOnLine(in, lines[kData].number,
               fmt::format("the PCD header has no {} line before DATA", kKeywords[keyword]));
  return lines[keyword];
}

uint64_t parseUnsigned(const InputStream& in, const HeaderLine& line, Keyword keyword,
                       size_t index) {
  int64_t value = 0;
  if (!parseInteger(line.values[index], value) || value < 0)
    failOnLine(in, line.number,
               fmt::format("{} value '{}' is not a non-negative integer", kKeywords[keyword],
                           line.values[index]));
  return static_cast<uint64_t>(value);
}

uint64_t singleNumber(const InputStream& in, const HeaderLines& lines, Keyword keyword) {
  const HeaderLine& line = requiredLine(in, lines, keyword);
  if (line.values.size() != 1)
    failOnLine(in, line.number,
               fmt::format("{} needs one value, not {}", kKeywords[keyword], line.values.size()));
  return parseUnsigned(in, line, keyword, 0);
}

// The fields from FIELDS, SIZE, TYPE and COUNT (optional before v0.7: one value each).
std::vector<PcdField> parseFields(const InputStream& in, const HeaderLines& lines) {
  const HeaderLine& names = requiredLine(in, lines, kFields);
  for (const Keyword keyword : {kSize, kType, kCount}) {
    const HeaderLine& line = keyword == kCount ? lines[kCount] : requiredLine(in, lines, keyword);
    if (line.number != 0 && line.values.size() != names.values.size())
      failOnLine(in, line.number,
                 fmt::format("{} has {} values for the {} FIELDS", kKeywords[keyword],
                             line.values.size(), names.values.size()));
  }
  std::vector<PcdField> fields(names.values.size());
  uint64_t recordBytes = 0;
  for (size_t i = 0; i < fields.size(); ++i) {
    PcdField& field = fields[i];
    field.name = names.values[i];
    field.size = parseUnsigned(in, lines[kSize], kSize, i);
    const std::string& letter = lines[kType].values[i];
    const auto* code = std::find_if(kTypeCodes.begin(), kTypeCodes.end(), [&](const TypeCode& c) {
      return c.letter == letter && c.size == field.size;
    });
    if (code == kTypeCodes.end())
      failOnLine(in, lines[kType].number,
                 fmt::format("field '{}' has TYPE {} with SIZE {} (supported: I and U of 1, 2, "
                             "4 or 8 bytes, F of 4 or 8)",
                             field.name, letter, field.size));
    field.type = code->type;
    if (lines[kCount].number != 0) field.count = parseUnsigned(in, lines[kCount], kCount, i);
    if (field.count == 0 || field.count > kMaxRecordBytes)
      failOnLine(in, lines[kCount].number,
                 fmt::format("field '{}' has COUNT {} (supported: 1 to {})", field.name,
                             field.count, kMaxRecordBytes));
    recordBytes += field.size * field.count;
    if (recordBytes > kMaxRecordBytes)
      failOnLine(
          in, names.number,
          fmt::format("a point of these fields exceeds the {} bytes supported", kMaxRecordBytes));
  }
  return fields;
}

PcdData parseDataKind(const InputStream& in, const HeaderLine& line) {
  const std::string kind = line.values.empty() ? "" : line.values[0];
  if (kind == "ascii") return PcdData::kAscii;
  if (kind == "binary") return PcdData::kBinary;
  if (kind == "binary_compressed") return PcdData::kBinaryCompressed;
  failOnLine(
      in, line.number,
      fmt::format("unknown DATA kind '{:.40}' (known: ascii, binary, binary_compressed)", kind));
}

// Choose the field of each slot: the first name of the slot that a field has. Normals and separate
// colors are used only when all three are there; a packed color wins over separate ones.
void findSlots(const InputStream& in, const HeaderLines& lines, PcdHeader& header) {
  for (size_t slot = 0; slot < kSlotCount; ++slot) {
    header.slotField[slot] = -1;
    for (std::string_view name : kSlotNames[slot]) {
      if (name.empty() || header.slotField[slot] >= 0) continue;
      const auto found = std::find_if(header.fields.begin(), header.fields.end(),
                                      [&](const PcdField& field) { return field.name == name; });
      if (found != header.fields.end())
        header.slotField[slot] = static_cast<int>(found - header.fields.begin());
    }
  }
  for (const Slot axis : {kX, kY, kZ})
    if (header.slotField[axis] < 0)
      failOnLine(in, lines[kFields].number,
                 fmt::format("no field '{}' (x, y and z are required)", kSlotNames[axis][0]));
  const auto hasAll = [&](Slot first) {
    return header.slotField[first] >= 0 && header.slotField[first + 1] >= 0 &&
           header.slotField[first + 2] >= 0;
  };
  header.hasNormals = hasAll(kNx);
  const bool hasPacked = header.slotField[kPackedColor] >= 0;
  const bool hasSeparate = !hasPacked && hasAll(kRed);
  header.hasColors = hasPacked || hasSeparate;
  for (size_t slot = kNx; slot <= kNz; ++slot)
    if (!header.hasNormals) header.slotField[slot] = -1;
  for (size_t slot = kRed; slot <= kBlue; ++slot)
    if (!hasSeparate) header.slotField[slot] = -1;
}

// The fields that are read must hold one value each, and a packed color four bytes.
void checkUsedFields(const InputStream& in, const HeaderLines& lines, const PcdHeader& header) {
  for (size_t slot = 0; slot < kSlotCount; ++slot) {
    if (header.slotField[slot] < 0) continue;
    const PcdField& field = header.fields[static_cast<size_t>(header.slotField[slot])];
    if (field.count != 1)
      failOnLine(in, lines[kCount].number,
                 fmt::format("field '{}' has COUNT {}; coordinates, normals and colors need 1",
                             field.name, field.count));
    if (slot == kPackedColor && field.size != 4)
      failOnLine(in, lines[kSize].number,
                 fmt::format("packed color field '{}' has SIZE {}, not 4", field.name, field.size));
  }
}

PcdHeader readHeader(InputStream& in) {
  const HeaderLines lines = readHeaderLines(in);
  PcdHeader header;
  header.data = parseDataKind(in, lines[kData]);
  header.fields = parseFields(in, lines);
  const uint64_t width = singleNumber(in, lines, kWidth);
  const uint64_t height = lines[kHeight].number != 0 ? singleNumber(in, lines, kHeight) : 1;
  header.points = singleNumber(in, lines, kPoints);
  const bool isProduct = height == 0 ? header.points == 0
                                     : width <= std::numeric_limits<uint64_t>::max() / height &&
                                           width * height == header.points;
  if (!isProduct)
    failOnLine(in, lines[kPoints].number,
               fmt::format("POINTS {} is not WIDTH {} x HEIGHT {}", header.points, width, height));
  findSlots(in, lines, header);
  checkUsedFields(in, lines, header);
  return header;
}

// Where a field lies within a point, in the unit of the data kind: bytes of a binary record, bytes
// of a binary_compressed point (PCL leaves the "_" padding fields out of those), or values of an
// ascii line.
uint64_t unitsOf(const PcdField& field, PcdData data) {
  if (data == PcdData::kAscii) return field.count;
  if (data == PcdData::kBinaryCompressed && field.name == "_") return 0;
  return field.size * field.count;
}

template <typename T>
T load(const std::byte* p) {
  return loadLittleEndian<T>(p);
}

// Call visit with a value of the C++ type of `type`, so that loops are compiled per type.
template <typename Visit>
void withType(ScalarType type, Visit&& visit) {
  switch (type) {
    case ScalarType::kInt8:
      return visit(int8_t{});
    case ScalarType::kInt16:
      return visit(int16_t{});
    case ScalarType::kInt32:
      return visit(int32_t{});
    case ScalarType::kInt64:
      return visit(int64_t{});
    case ScalarType::kUInt8:
      return visit(uint8_t{});
    case ScalarType::kUInt16:
      return visit(uint16_t{});
    case ScalarType::kUInt32:
      return visit(uint32_t{});
    case ScalarType::kUInt64:
      return visit(uint64_t{});
    case ScalarType::kFloat32:
      return visit(float{});
    case ScalarType::kFloat64:
      return visit(double{});
  }
}

bool isFloat(ScalarType type) {
  return type == ScalarType::kFloat32 || type == ScalarType::kFloat64;
}

// The value of full intensity of a separate color field, as the PLY reader has it: 16-bit codes
// 0–65535, floats 0–1, other integers 0–255.
double colorFullScale(ScalarType type) {
  if (isFloat(type)) return 1.0;
  if (type == ScalarType::kUInt16 || type == ScalarType::kInt16) return 65535.0;
  return 255.0;
}

// The linear color of packed 0xAARRGGBB bits; `table` is srgb16ToLinearTable(), looked up by the
// caller once per batch.
glm::vec3 packedColor(uint32_t bits, const std::array<float, 65536>& table) {
  const auto channel = [&](int shift) { return table[size_t{(bits >> shift) & 0xFFu} * 257]; };
  return {channel(16), channel(8), channel(0)};
}

// The values of one field for consecutive points, `stride` bytes apart from `first`.
struct Column {
  const std::byte* first = nullptr;
  size_t stride = 0;
  ScalarType type = ScalarType::kFloat32;
};
using Columns = std::array<Column, kSlotCount>;

template <typename Vec>
void decodeColumn(const Column& column, size_t count, Vec* out,
                  typename Vec::value_type Vec::*member) {
  using Out = typename Vec::value_type;
  withType(column.type, [&](auto zero) {
    using T = decltype(zero);
    const std::byte* p = column.first;
    for (size_t i = 0; i < count; ++i, p += column.stride) {
      if constexpr (std::is_same_v<Out, float> && std::is_same_v<T, double>) {
        out[i].*member = narrowToFloat(load<T>(p));
      } else {
        out[i].*member = static_cast<Out>(load<T>(p));
      }
    }
  });
}

// Decode one field to doubles `outStride` apart (an extra).
void decodeExtraColumn(const Column& column, size_t count, double* out, size_t outStride) {
  withType(column.type, [&](auto zero) {
    using T = decltype(zero);
    const std::byte* p = column.first;
    for (size_t i = 0; i < count; ++i, p += column.stride, out += outStride)
      *out = static_cast<double>(load<T>(p));
  });
}

// Decode one separate color channel to linear values; 8- and 16-bit codes through the table.
void decodeColorChannel(const Column& column, size_t count, glm::vec3* out,
                        float glm::vec3::*member) {
  const std::array<float, 65536>& table = srgb16ToLinearTable();
  const double fullScale = colorFullScale(column.type);
  withType(column.type, [&](auto zero) {
    using T = decltype(zero);
    const std::byte* p = column.first;
    for (size_t i = 0; i < count; ++i, p += column.stride) {
      if constexpr (std::is_same_v<T, uint8_t>) {
        out[i].*member = table[size_t{load<T>(p)} * 257];
      } else if constexpr (std::is_same_v<T, uint16_t>) {
        out[i].*member = table[load<T>(p)];
      } else {
        out[i].*member = linearFromSrgbScaled(static_cast<double>(load<T>(p)), fullScale);
      }
    }
  });
}

void decodePackedColors(const Column& column, size_t count, glm::vec3* out) {
  const std::array<float, 65536>& table = srgb16ToLinearTable();
  const std::byte* p = column.first;
  for (size_t i = 0; i < count; ++i, p += column.stride)
    out[i] = packedColor(load<uint32_t>(p), table);
}

// Current PCL writes a packed color in text as the integer value of its bits, older versions wrote
// the float whose bits hold it.
bool parsePackedColor(std::string_view text, uint32_t& bits) {
  int64_t integer = 0;
  if (parseInteger(text, integer)) {
    if (integer < std::numeric_limits<int32_t>::min() ||
        integer > std::numeric_limits<uint32_t>::max())
      return false;
    bits = static_cast<uint32_t>(integer);
    return true;
  }
  float single = 0.0f;
  if (!parseNumber(text, single) || std::isnan(single)) return false;  // a NaN's bits are lost
  bits = std::bit_cast<uint32_t>(single);
  return true;
}

// Parse a text value of a slot; F4 values are rounded to float directly, as if they were binary.
bool parseSlotValue(Slot slot, ScalarType type, std::string_view text, double& value) {
  if (slot == kPackedColor) {
    uint32_t bits = 0;
    if (!parsePackedColor(text, bits)) return false;
    value = bits;
    return true;
  }
  if (type != ScalarType::kFloat32) return parseNumber(text, value);
  float single = 0.0f;
  if (!parseNumber(text, single)) return false;
  value = single;
  return true;
}

class PcdPointReader final : public PointReader {
 public:
  PcdPointReader(InputStream in, bool keepExtras) : in_(std::move(in)), header_(readHeader(in_)) {
    uint64_t units = 0;
    for (const PcdField& field : header_.fields) {
      fieldStart_.push_back(units);
      units += unitsOf(field, header_.data);
    }
    // Extras: the single-valued fields no slot reads (not PCL's "_" padding).
    for (size_t f = 0; keepExtras && f < header_.fields.size(); ++f) {
      const bool read = std::find(header_.slotField.begin(), header_.slotField.end(), int(f)) !=
                        header_.slotField.end();
      if (read || header_.fields[f].count != 1 || header_.fields[f].name == "_") continue;
      extraFields_.push_back(f);
      info_.extraNames.push_back(header_.fields[f].name);
    }
    pointUnits_ = units;
    info_.path = in_.path();
    info_.declaredPoints = header_.points;
    info_.hasNormals = header_.hasNormals;
    info_.hasColors = header_.hasColors;
    switch (header_.data) {
      case PcdData::kAscii:
        info_.format = "pcd-ascii";
        mapValuesToSlots();
        break;
      case PcdData::kBinary:
        info_.format = "pcd-binary";
        checkAgainstFileSize();
        break;
      case PcdData::kBinaryCompressed:
        info_.format = "pcd-binary-compressed";
        if (header_.points > 0) readBlockSizes();
        break;
    }
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    size_t appended = 0;
    switch (header_.data) {
      case PcdData::kAscii:
        appended = readAscii(out, maxPoints);
        break;
      case PcdData::kBinary:
        appended = readBinary(out, maxPoints);
        break;
      case PcdData::kBinaryCompressed:
        appended = readBlock(out, maxPoints);
        break;
    }
    stats_.pointsRead += appended;
    return appended;
  }

 private:
  [[noreturn]] void failEndsEarly() {
    in_.fail(fmt::format("file ends after {} of {} points", pointsDone_, header_.points));
  }

  // Reject binary records that cannot be all there, before reading them, when the size is known.
  void checkAgainstFileSize() {
    if (!in_.knownSize()) return;
    const uint64_t start = in_.offset();
    const uint64_t available = (*in_.knownSize() - start) / pointUnits_;
    if (available < header_.points)
      in_.failAt(start + available * pointUnits_,
                 fmt::format("file ends after {} of {} points", available, header_.points));
  }

  // The block starts with its compressed and uncompressed sizes (uint32 each). Check them against
  // the header and the file before anything is allocated.
  void readBlockSizes() {
    const uint64_t at = in_.offset();
    std::array<std::byte, 8> sizes{};
    if (!in_.readExact(sizes.data(), sizes.size()))
      in_.failAt(at, "file ends before the sizes of the binary_compressed block");
    compressedBytes_ = load<uint32_t>(sizes.data());
    blockBytes_ = load<uint32_t>(sizes.data() + 4);
    const bool fits = header_.points <= std::numeric_limits<uint32_t>::max() / pointUnits_;
    if (!fits || blockBytes_ != header_.points * pointUnits_)
      in_.failAt(at + 4, fmt::format("the binary_compressed block holds {} bytes, not POINTS {} x "
                                     "{} bytes per point",
                                     blockBytes_, header_.points, pointUnits_));
    if (blockBytes_ > compressedBytes_ * kMaxLzfExpansion)
      in_.failAt(at, fmt::format("{} LZF-compressed bytes cannot hold the {} bytes the "
                                 "binary_compressed block declares",
                                 compressedBytes_, blockBytes_));
    if (in_.knownSize() && compressedBytes_ > *in_.knownSize() - in_.offset())
      in_.failAt(*in_.knownSize(),
                 fmt::format("file ends inside the binary_compressed block ({} of {} bytes)",
                             *in_.knownSize() - in_.offset(), compressedBytes_));
  }

  std::vector<std::byte> readCompressedBytes() {
    const uint64_t start = in_.offset();
    std::vector<std::byte> bytes;
    if (in_.knownSize()) bytes.reserve(compressedBytes_);  // checked against the file size
    while (bytes.size() < compressedBytes_) {
      const size_t done = bytes.size();
      const size_t chunk = std::min<size_t>(kCompressedChunkBytes, compressedBytes_ - done);
      bytes.resize(done + chunk);
      if (!in_.readExact(bytes.data() + done, chunk))
        in_.fail(fmt::format("file ends inside the binary_compressed block ({} of {} bytes)",
                             in_.offset() - start, compressedBytes_));
    }
    return bytes;
  }

  // Decompress the whole block: PCL writes it as one LZF stream, which cannot be split.
  void decompressBlock() {
    const uint64_t at = in_.offset();
    const std::vector<std::byte> compressed = readCompressedBytes();
    block_ = std::make_unique_for_overwrite<std::byte[]>(blockBytes_);
    errno = 0;
    const unsigned int size =
        lzf_decompress(compressed.data(), static_cast<unsigned int>(compressedBytes_), block_.get(),
                       static_cast<unsigned int>(blockBytes_));
    if (size == blockBytes_) return;
    block_.reset();
    if (size == 0 && errno == E2BIG)
      in_.failAt(at, fmt::format("the LZF data of the binary_compressed block decompresses to "
                                 "more than the {} bytes it declares",
                                 blockBytes_));
    if (size == 0) in_.failAt(at, "the LZF data of the binary_compressed block is corrupt");
    in_.failAt(at, fmt::format("the LZF data of the binary_compressed block decompresses to {} "
                               "bytes, not the {} it declares",
                               size, blockBytes_));
  }

  size_t readBlock(PointCloud& out, size_t maxPoints) {
    if (pointsDone_ == header_.points) return 0;
    if (!block_) decompressBlock();
    size_t appended = 0;
    while (appended < maxPoints && pointsDone_ < header_.points) {
      const size_t count = static_cast<size_t>(
          std::min<uint64_t>(maxPoints - appended, header_.points - pointsDone_));
      std::vector<Column> extras;
      for (const size_t f : extraFields_)
        extras.push_back({block_.get() + fieldStart_[f] * header_.points +
                              pointsDone_ * header_.fields[f].size,
                          header_.fields[f].size, header_.fields[f].type});
      appended += appendPoints(blockColumns(), extras, count, out);
      pointsDone_ += count;
    }
    if (pointsDone_ == header_.points) block_.reset();
    return appended;
  }

  // The columns of the slots for the next point of the block: fields one after the other.
  Columns blockColumns() const {
    Columns columns{};
    for (size_t slot = 0; slot < kSlotCount; ++slot) {
      if (header_.slotField[slot] < 0) continue;
      const size_t field = static_cast<size_t>(header_.slotField[slot]);
      const PcdField& f = header_.fields[field];
      const uint64_t start = fieldStart_[field] * header_.points + pointsDone_ * f.size;
      columns[slot] = {block_.get() + start, f.size, f.type};
    }
    return columns;
  }

  size_t readBinary(PointCloud& out, size_t maxPoints) {
    size_t appended = 0;
    while (appended < maxPoints && pointsDone_ < header_.points) {
      const std::span<const std::byte> bytes = in_.peek(pointUnits_);
      if (bytes.size() < pointUnits_) failEndsEarly();
      const size_t count = static_cast<size_t>(std::min<uint64_t>(
          {bytes.size() / pointUnits_, maxPoints - appended, header_.points - pointsDone_}));
      std::vector<Column> extras;
      for (const size_t f : extraFields_)
        extras.push_back({bytes.data() + fieldStart_[f], pointUnits_, header_.fields[f].type});
      appended += appendPoints(recordColumns(bytes.data()), extras, count, out);
      in_.consume(count * pointUnits_);
      pointsDone_ += count;
    }
    return appended;
  }

  Columns recordColumns(const std::byte* records) const {
    Columns columns{};
    for (size_t slot = 0; slot < kSlotCount; ++slot) {
      if (header_.slotField[slot] < 0) continue;
      const size_t field = static_cast<size_t>(header_.slotField[slot]);
      columns[slot] = {records + fieldStart_[field], pointUnits_, header_.fields[field].type};
    }
    return columns;
  }

  // Decode `count` points from columns into out, dropping non-finite positions; returns the
  // points appended. Column by column dispatches on the type once per batch, not per value.
  size_t appendPoints(const Columns& columns, const std::vector<Column>& extras, size_t count,
                      PointCloud& out) {
    static constexpr double glm::dvec3::*kPositionMembers[] = {&glm::dvec3::x, &glm::dvec3::y,
                                                               &glm::dvec3::z};
    static constexpr float glm::vec3::*kMembers[] = {&glm::vec3::x, &glm::vec3::y, &glm::vec3::z};
    const size_t first = out.positions.size();
    out.positions.resize(first + count);
    for (int axis = 0; axis < 3; ++axis)
      decodeColumn(columns[kX + axis], count, out.positions.data() + first, kPositionMembers[axis]);
    if (header_.hasNormals) {
      out.normals.resize(first + count);
      for (int axis = 0; axis < 3; ++axis)
        decodeColumn(columns[kNx + axis], count, out.normals.data() + first, kMembers[axis]);
    }
    if (header_.hasColors) {
      out.colors.resize(first + count);
      if (header_.slotField[kPackedColor] >= 0) {
        decodePackedColors(columns[kPackedColor], count, out.colors.data() + first);
      } else {
        for (int channel = 0; channel < 3; ++channel)
          decodeColorChannel(columns[kRed + channel], count, out.colors.data() + first,
                             kMembers[channel]);
      }
    }
    if (!extras.empty()) {
      out.extraNames = info_.extraNames;
      out.extras.resize((first + count) * extras.size());
      for (size_t e = 0; e < extras.size(); ++e)
        decodeExtraColumn(extras[e], count, out.extras.data() + first * extras.size() + e,
                          extras.size());
    }
    // PCL marks the invalid points of organized clouds with NaN.
    const size_t removed = removeNonFinite(out, first);
    stats_.droppedNonFinite += removed;
    return count - removed;
  }

  // Record the slot of each value of an ascii line, -1 for values not read.
  void mapValuesToSlots() {
    slotOfValue_.assign(pointUnits_, -1);
    extraOfValue_.assign(pointUnits_, -1);
    for (size_t e = 0; e < extraFields_.size(); ++e)
      extraOfValue_[fieldStart_[extraFields_[e]]] = int(e);
    for (size_t slot = 0; slot < kSlotCount; ++slot)
      if (header_.slotField[slot] >= 0)
        slotOfValue_[fieldStart_[static_cast<size_t>(header_.slotField[slot])]] =
            static_cast<int8_t>(slot);
  }

  size_t readAscii(PointCloud& out, size_t maxPoints) {
    size_t appended = 0;
    std::string_view line;
    while (appended < maxPoints && pointsDone_ < header_.points) {
      if (!in_.readLine(line)) failEndsEarly();
      std::string_view rest = line;
      std::string_view value;
      if (!nextField<isBlank>(rest, value)) continue;  // a blank line
      appended += parseLine(line, out) ? 1 : 0;
      ++pointsDone_;
    }
    return appended;
  }

  // Parse a data line; false when its point was dropped for a non-finite coordinate.
  bool parseLine(std::string_view line, PointCloud& out) {
    std::array<double, kSlotCount> values{};
    lineExtras_.assign(extraFields_.size(), 0.0);
    std::string_view text;
    size_t column = 0;
    for (; nextField<isBlank>(line, text); ++column) {
      if (column < extraOfValue_.size() && extraOfValue_[column] >= 0) {
        const PcdField& field = header_.fields[extraFields_[size_t(extraOfValue_[column])]];
        if (!parseNumber(text, lineExtras_[size_t(extraOfValue_[column])]))
          in_.failLine(fmt::format("value {} (field '{}') is not a number: '{:.40}'", column + 1,
                                   field.name, text));
      }
      if (column >= slotOfValue_.size() || slotOfValue_[column] < 0) continue;
      const auto slot = static_cast<Slot>(slotOfValue_[column]);
      const PcdField& field = header_.fields[static_cast<size_t>(header_.slotField[slot])];
      if (!parseSlotValue(slot, field.type, text, values[slot]))
        in_.failLine(fmt::format("value {} (field '{}') is not a {}: '{:.40}'", column + 1,
                                 field.name, slot == kPackedColor ? "color" : "number", text));
    }
    if (column != slotOfValue_.size())
      in_.failLine(fmt::format("expected {} values, found {}", slotOfValue_.size(), column));
    return appendValues(values, out);
  }

  bool appendValues(const std::array<double, kSlotCount>& values, PointCloud& out) {
    const glm::dvec3 position{values[kX], values[kY], values[kZ]};
    if (!isFinite(position)) {
      ++stats_.droppedNonFinite;
      return false;
    }
    out.positions.push_back(position);
    if (!extraFields_.empty()) {
      out.extraNames = info_.extraNames;
      out.extras.insert(out.extras.end(), lineExtras_.begin(), lineExtras_.end());
    }
    if (header_.hasNormals)
      out.normals.emplace_back(narrowToFloat(values[kNx]), narrowToFloat(values[kNy]),
                               narrowToFloat(values[kNz]));
    if (!header_.hasColors) return true;
    if (header_.slotField[kPackedColor] >= 0) {
      out.colors.push_back(
          packedColor(static_cast<uint32_t>(values[kPackedColor]), srgb16ToLinearTable()));
      return true;
    }
    const auto channel = [&](Slot slot) {
      const ScalarType type = header_.fields[static_cast<size_t>(header_.slotField[slot])].type;
      return linearFromSrgbScaled(values[slot], colorFullScale(type));
    };
    out.colors.emplace_back(channel(kRed), channel(kGreen), channel(kBlue));
    return true;
  }

  InputStream in_;
  PcdHeader header_;
  std::vector<uint64_t> fieldStart_;    // per field: where it starts in a point (see unitsOf)
  uint64_t pointUnits_ = 0;             // size of a point in the same unit
  std::vector<int8_t> slotOfValue_;     // ascii: the slot of each value of a line, or -1
  std::vector<size_t> extraFields_;     // the fields read as extras (ReadOptions::keepExtras)
  std::vector<int> extraOfValue_;       // ascii: the extra of each value of a line, or -1
  std::vector<double> lineExtras_;      // ascii: the extras of the line being parsed
  uint64_t compressedBytes_ = 0;        // binary_compressed: the LZF data's size
  uint64_t blockBytes_ = 0;             // binary_compressed: the decompressed block's size
  std::unique_ptr<std::byte[]> block_;  // the decompressed block while points remain in it
  uint64_t pointsDone_ = 0;             // points (or records) consumed, dropped ones included
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

bool looksLikePcd(InputStream& in) {
  const std::span<const std::byte> bytes = in.peek(4096);
  std::string_view rest(reinterpret_cast<const char*>(bytes.data()),
                        std::min<size_t>(bytes.size(), 4096));
  while (!rest.empty()) {
    const size_t end = std::min(rest.find('\n'), rest.size());
    std::string_view line = rest.substr(0, end);
    rest.remove_prefix(std::min(end + 1, rest.size()));
    if (line.starts_with("# .PCD")) return true;
    std::string_view keyword;
    if (!nextField<isBlank>(line, keyword) || keyword.starts_with('#')) continue;
    return keyword == "VERSION" || keyword == "FIELDS";
  }
  return false;
}

std::unique_ptr<PointReader> makePcdReader(InputStream in, bool keepExtras) {
  return std::make_unique<PcdPointReader>(std::move(in), keepExtras);
}

}  // namespace iso::io
