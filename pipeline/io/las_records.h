// The variable length records of LAS files that the LAS reader uses: those that declare the
// coordinate system (ASPRS LAS 1.4 R15 §2.5 "Variable Length Records", §2.8 "Extended Variable
// Length Records", §2.9–2.10 "Coordinate Reference System VLRs"; GeoTIFF 1.0 §2.4 for the keys).
// Records are read where they are (VLRs between the public header and the point data, EVLRs after
// the point data) and others are skipped. Broken records do not stop the points from being read:
// they are ignored with a note naming the record and the problem.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/las_format.h"
#include "pipeline/io/readers.h"

namespace iso::io {

// The coordinate system records of one file, in the order they were found.
class LasCoordinateRecords {
 public:
  // Whether a record of this user and id declares the coordinate system.
  static bool isWanted(std::string_view userId, uint16_t recordId);
  // Keep a wanted record; `where` names it ("VLR", "EVLR").
  void add(uint16_t recordId, std::span<const std::byte> payload, std::string_view where);
  bool hasWkt() const { return !wkt_.empty(); }
  // The coordinate system the records declare (the first record of each kind counts), or nullopt;
  // problems with the GeoTIFF keys are appended to notes.
  std::optional<CoordinateSystem> coordinateSystem(std::vector<std::string>& notes) const;

 private:
  std::string wkt_;
  std::vector<uint16_t> geoKeys_;  // 34735: the key directory
  std::string geoAscii_;           // 34737: the ASCII parameters
  std::vector<std::string> sources_;
};

// Read the `count` VLRs from the stream, which is at the end of the public header, keeping the
// wanted ones (and the LASzip VLR's payload in laszip, when given and present); the stream is
// left at the end of the last VLR read (FileError when the file ends before it).
void readLasVlrs(InputStream& in, uint64_t pointDataOffset, uint32_t count,
                 LasCoordinateRecords& records, std::vector<std::string>& notes,
                 std::vector<std::byte>* laszip = nullptr);

// Read the `count` EVLRs of a LAS 1.4 file from `start` (after `pointDataEnd`), keeping the wanted
// ones. Opens the file again, so the points' stream is not moved.
void readLasEvlrs(const std::filesystem::path& path, uint64_t start, uint32_t count,
                  uint64_t pointDataEnd, LasCoordinateRecords& records,
                  std::vector<std::string>& notes);

// The coordinate system of a LAS or LAZ file: from its VLRs, else from the EVLRs of LAS 1.4
// (which start after pointDataEnd). The stream is at the start of the file, and is left at the
// end of the VLRs. The LASzip VLR's payload goes to laszip when given.
std::optional<CoordinateSystem> readLasCoordinateSystem(InputStream& in, const LasHeader& header,
                                                        uint64_t pointDataEnd,
                                                        std::vector<std::string>& notes,
                                                        std::vector<std::byte>* laszip = nullptr);

// The LASzip VLR: user "laszip encoded", record 22204.
inline constexpr std::string_view kLaszipUser = "laszip encoded";
inline constexpr uint16_t kLaszipRecord = 22204;

}  // namespace iso::io
