// What the E57 reader takes from a file's XML section (ASTM E2807 section 8.4 and 9, "Data3D"):
// for each point cloud of /data3D, in order, its name, pose, color limits and the CompressedVector
// of its points (where its binary section is, how many records it holds, and the prototype that
// says how each record is encoded). Everything else is skipped.
//
// The XML is untrusted: it is parsed by expat as a stream, page by page, and refused
// (iso::FileError naming the file, the byte and the XML line) when it is malformed, has a DOCTYPE
// (E57 needs none, and refusing it stops any entity expansion), nests deeper than kE57MaxXmlDepth,
// is longer than kE57MaxXmlBytes, declares more than kE57MaxScans point clouds or kE57MaxFields
// fields in a prototype (kE57MaxFieldsInAll in all), holds a malformed number, a prototype field of
// a type that records cannot hold, a codec other than bitpack, or a point cloud without its points.
// What the values mean (which fields are there, whether a pose is a rotation) is the reader's to
// check.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/io/e57_pages.h"

namespace iso::io {

inline constexpr uint64_t kE57MaxXmlBytes = uint64_t{64} << 20;
inline constexpr size_t kE57MaxXmlDepth = 64;
inline constexpr size_t kE57MaxScans = size_t{1} << 16;
inline constexpr size_t kE57MaxFields = 1024;                  // per prototype
inline constexpr size_t kE57MaxFieldsInAll = size_t{1} << 19;  // in all prototypes together

// How a prototype field's values are stored in its bytestream (bitpack codec, E2807 Table 26).
enum class E57Encoding : uint8_t {
  kSingle,        // Float precision="single": 32-bit IEEE
  kDouble,        // Float precision="double": 64-bit IEEE
  kInteger,       // Integer: value - minimum in bitWidth bits
  kScaledInteger  // ScaledInteger: (value - minimum) in bitWidth bits; value * scale + offset
};

struct E57Field {
  std::string name;  // as in the XML, with its namespace prefix if any ("nor:normalX")
  E57Encoding encoding = E57Encoding::kDouble;
  int64_t minimum = 0;  // integers
  int64_t maximum = 0;
  double scale = 1.0;  // scaled integers
  double offset = 0.0;
  // The range its values claim (the minimum and maximum attributes, scaled for scaled integers);
  // Floats without them claim nothing.
  std::optional<double> lowest;
  std::optional<double> highest;

  // Bits per value in the bytestream: 32 or 64 for floats, the width of maximum - minimum for
  // integers (0 when they are equal: every value is the minimum and takes no bytes).
  uint32_t bitWidth() const;
};

struct E57Scan {
  std::string name;  // empty when none (its first 100 bytes)
  std::string guid;
  std::array<double, 4> rotation{1.0, 0.0, 0.0, 0.0};  // quaternion w, x, y, z (not normalized)
  std::array<double, 3> translation{0.0, 0.0, 0.0};
  // colorLimits: red, green, blue minimum and maximum, where given.
  std::array<std::optional<double>, 3> colorMinimum;
  std::array<std::optional<double>, 3> colorMaximum;
  uint64_t fileOffset = 0;  // physical offset of the CompressedVector binary section
  uint64_t recordCount = 0;
  std::vector<E57Field> prototype;  // in prototype order, which is the bytestreams' order
};

// How a scan is named in messages: "scan 2 'Station 3'" (numbered from 1 in data3D order), or
// "scan 2" when it has no name; `index` counts from 0.
std::string e57ScanLabel(const E57Scan& scan, size_t index);

// Parse the XML section that the header locates. Throws iso::FileError.
std::vector<E57Scan> readE57Scans(E57Pages& pages, const E57Header& header);

}  // namespace iso::io
