// The physical layer of an E57 file (ASTM E2807, section 8 "File structure"): the 48-byte file
// header, and pages of pageSize bytes whose last 4 hold a CRC-32C (Castagnoli) of the others,
// stored big endian (the standard's one big-endian field). The data bytes of consecutive pages form
// the "logical" byte stream in which the XML section and the binary sections lie; offsets in the
// XML and in section headers are physical (file) offsets. Every page read is checked.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/io/input_stream.h"

namespace iso::io {

// Refused page sizes: the 48-byte header must lie in the data of the first page, and a page of
// more than 1 MiB is no E57 writer's (the standard's writers use 1024).
inline constexpr uint64_t kE57MinPageSize = 64;
inline constexpr uint64_t kE57MaxPageSize = uint64_t{1} << 20;
inline constexpr uint64_t kE57ChecksumSize = 4;

// The file header (E2807 Table 1), all fields little endian, at byte 0.
struct E57Header {
  uint32_t versionMajor = 0;
  uint32_t versionMinor = 0;
  uint64_t physicalLength = 0;     // the file's size in bytes
  uint64_t xmlPhysicalOffset = 0;  // where the XML section starts
  uint64_t xmlLogicalLength = 0;   // its length in logical bytes
  uint64_t pageSize = 0;
};

// Read and check the header against the file: signature, version 1.x, a supported page size, the
// physical length equal to the file's size and a whole number of pages. Throws iso::FileError.
// gzip-compressed E57 files are refused (their size is unknown without decompressing them all,
// and sections are read out of order).
E57Header readE57Header(InputStream& in);

// The pages of a file whose header was checked, read through `in` (which must outlive this).
// Used by one thread at a time.
class E57Pages {
 public:
  E57Pages(InputStream& in, const E57Header& header);

  InputStream& stream() const { return in_; }
  // Logical bytes in the file (its data bytes, checksums left out).
  uint64_t logicalLength() const { return pageCount_ * dataSize_; }
  uint64_t physicalOffset(uint64_t logical) const {
    return logical / dataSize_ * pageSize_ + logical % dataSize_;
  }
  // The logical offset of a physical one; nullopt past the file's end or inside a checksum.
  std::optional<uint64_t> logicalOffset(uint64_t physical) const;

  // Copy `count` logical bytes from `logical` on to `out`, checking the CRC-32C of each page
  // loaded. The bytes must lie inside the file (logicalLength()). Throws iso::FileError naming the
  // page and its byte offset on a mismatch.
  void read(uint64_t logical, std::byte* out, size_t count);

 private:
  void loadPage(uint64_t page);

  InputStream& in_;
  uint64_t pageSize_;
  uint64_t dataSize_;
  uint64_t pageCount_;
  std::vector<std::byte> page_;  // the data bytes of loadedPage_
  std::optional<uint64_t> loadedPage_;
};

}  // namespace iso::io
