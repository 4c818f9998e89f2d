// The PLY header (Greg Turk's format, "PLY 1.0"): elements with counts, scalar and list properties,
// and decoding of binary values. Shared by the PLY point and mesh readers.
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "pipeline/io/input_stream.h"

namespace iso::io {

enum class PlyType : uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };
enum class PlyEncoding : uint8_t { Ascii, BinaryLittleEndian, BinaryBigEndian };

size_t plyTypeSize(PlyType type);
bool isPlyInteger(PlyType type);
// The PointFileInfo::format of the encoding: "ply-ascii", "ply-binary-le", "ply-binary-be".
const char* plyFormatName(PlyEncoding encoding);

struct PlyProperty {
  std::string name;
  PlyType type;                      // of the value, or of a list's items
  std::optional<PlyType> countType;  // set for a list property
  bool isList() const { return countType.has_value(); }
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;

  bool hasLists() const;
  // Bytes of one binary record, counting no list.
  size_t scalarBytes() const;
  // Index of the first property with one of the names, if any.
  std::optional<size_t> find(std::initializer_list<std::string_view> names) const;
};

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::Ascii;
  std::vector<PlyElement> elements;
  // Index of the first element with this name, if any.
  std::optional<size_t> find(std::string_view name) const;
};

// Read the header from "ply" to "end_header", leaving the stream at the first element's data.
// Throws iso::FileError naming the line for a malformed or unsupported header.
PlyHeader readPlyHeader(InputStream& in);

// Read past every record of the element. Throws iso::FileError when the file ends first.
void skipPlyElement(InputStream& in, PlyEncoding encoding, const PlyElement& element);

// Decode a binary value of the given type at p (bytes in file order).
template <bool kBigEndian, typename T>
T loadPlyRaw(const std::byte* p) {
  std::array<std::byte, sizeof(T)> bytes;
  std::memcpy(bytes.data(), p, sizeof(T));
  if constexpr (kBigEndian != (std::endian::native == std::endian::big)) {
    for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
  }
  return std::bit_cast<T>(bytes);
}

template <bool kBigEndian>
double loadPlyScalar(PlyType type, const std::byte* p) {
  switch (type) {
    case PlyType::Int8:
      return loadPlyRaw<kBigEndian, int8_t>(p);
    case PlyType::UInt8:
      return loadPlyRaw<kBigEndian, uint8_t>(p);
    case PlyType::Int16:
      return loadPlyRaw<kBigEndian, int16_t>(p);
    case PlyType::UInt16:
      return loadPlyRaw<kBigEndian, uint16_t>(p);
    case PlyType::Int32:
      return loadPlyRaw<kBigEndian, int32_t>(p);
    case PlyType::UInt32:
      return loadPlyRaw<kBigEndian, uint32_t>(p);
    case PlyType::Float32:
      return loadPlyRaw<kBigEndian, float>(p);
    case PlyType::Float64:
      return loadPlyRaw<kBigEndian, double>(p);
  }
  return 0.0;
}

// Decode a binary integer (a list count or index; the header guarantees an integer type).
template <bool kBigEndian>
int64_t loadPlyInteger(PlyType type, const std::byte* p) {
  if (type == PlyType::Float32 || type == PlyType::Float64) return -1;
  return int64_t(loadPlyScalar<kBigEndian>(type, p));  // every integer type is exact in double
}

inline int64_t loadPlyInteger(PlyEncoding encoding, PlyType type, const std::byte* p) {
  return encoding == PlyEncoding::BinaryBigEndian ? loadPlyInteger<true>(type, p)
                                                  : loadPlyInteger<false>(type, p);
}

// Read the count of a binary list; throws iso::FileError when the file ends or it is negative.
uint64_t readPlyListCount(InputStream& in, PlyEncoding encoding, PlyType countType);

}  // namespace iso::io
