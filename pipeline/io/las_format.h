// The LAS public header and point records, shared by the LAS and LAZ readers (ASPRS LAS
// Specification 1.4 R15, section 2.4 "Public Header Block" and 2.6–2.16 "Point Data Records";
// all fields little endian). A LAZ file is a LAS file whose point data is LASzip-compressed: the
// same header (with bit 7 of the point format set) and, once decoded, the same records.
#pragma once

#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/readers.h"

namespace iso::io {

struct LasHeader {
  int versionMajor = 1;
  int versionMinor = 2;
  uint64_t headerSize = 0;
  uint64_t pointDataOffset = 0;
  uint32_t vlrCount = 0;
  uint64_t evlrStart = 0;     // LAS 1.4
  uint32_t evlrCount = 0;     // LAS 1.4
  int pointFormat = 0;        // without the compression bits
  bool isCompressed = false;  // LASzip: bit 7 (bit 6 in early versions) of the format byte
  uint64_t recordLength = 0;
  uint64_t pointCount = 0;
  glm::dvec3 scale{1.0};
  glm::dvec3 offset{0.0};
};

// Read and check the public header at the start of the stream, which is left where it was.
// Throws FileError for a file that is not LAS or whose fixed fields are inconsistent.
LasHeader readLasHeader(InputStream& in);

// "las 1.2 format 2", or "laz ..." for a compressed file.
std::string lasFormatName(const LasHeader& header);

// Bytes from the start of a record of the point format to its RGB channels; 0 when it has none.
size_t lasRgbOffset(int pointFormat);

// How the 16-bit RGB fields of a file hold its colors.
enum class LasColorCoding : uint8_t { kEight, kEightTimes256, kSixteen };

// The records whose colors decide the coding: the first min(count, 65536, 16 MiB of records).
uint64_t lasColorProbeRecords(const LasHeader& header);

// Many writers store 8-bit colors in the 16-bit RGB fields, as they are (0–255) or times 256
// (0–65280, every low byte 0). Decided from the given records (the probe's): none above 255 is
// 8-bit; every low byte 0 is 8-bit times 256; otherwise 16-bit.
LasColorCoding probeLasColorCoding(const LasHeader& header, const std::byte* records, size_t count);

// The note a reader adds for 8-bit colors times 256.
inline constexpr const char* kLasColorsTimes256Note =
    "its colors are 8-bit codes times 256 (every low byte 0): read as 8-bit codes";

// The extras a LAS point format gives (ReadOptions::keepExtras): "intensity", "return_number",
// "classification" and, for formats with a GPS time (1, 3–10), "gps_time".
std::vector<std::string> lasExtraNames(int pointFormat);

// Point records to points: positions (integers times scale plus offset), colors decoded by the
// coding, and when asked the extras of lasExtraNames.
class LasRecordDecoder {
 public:
  LasRecordDecoder(const LasHeader& header, LasColorCoding coding, bool keepExtras);
  // The extras appended per point (lasExtraNames, or none).
  const std::vector<std::string>& extraNames() const { return extraNames_; }
  // Append `count` records to out, dropping (and counting in stats) non-finite positions;
  // returns the points appended.
  size_t append(const std::byte* records, size_t count, PointCloud& out, ReadStats& stats) const;

 private:
  glm::dvec3 scale_, offset_;
  size_t recordLength_;
  size_t rgbAt_;
  LasColorCoding coding_;
  bool extended_;  // formats 6-10
  std::vector<std::string> extraNames_;
};

}  // namespace iso::io
