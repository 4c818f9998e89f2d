// The LASzip container around a LAZ file's point data: the LASzip VLR (how the points are
// compressed) and the chunk table (where each chunk lies and how many points it holds), as
// LASzip and laz-perf write them. Decoding the chunks is laz_decoder.h's.
//
// Point data of a chunked LAZ file: at the header's point data offset a signed 64-bit offset of
// the chunk table (−1: the table's offset is in the file's last 8 bytes instead), then the
// chunks, one after another. The table: version u32 (0), number of chunks u32, then for each
// chunk its number of points (only when the VLR's chunk size is 0xFFFFFFFF, "variable") and its
// size in bytes, compressed with LASzip's arithmetic coder (32-bit integer compressor, the count
// in context 0 and the size in context 1, each predicted by the previous chunk's).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/las_format.h"

namespace iso::io {

inline constexpr uint32_t kLazVariableChunkSize = 0xFFFFFFFF;

struct LazChunk {
  uint64_t offset = 0;  // in the file
  uint64_t bytes = 0;
  uint64_t points = 0;
};

// Check the LASzip VLR's payload against what laz-perf decodes for the header's point format
// (compressor, coder, and each item's type, size and version); returns the chunk size. Throws
// FileError (at the file's start) naming what is not supported or inconsistent.
uint32_t checkLaszipRecord(const InputStream& in, const LasHeader& header,
                           std::span<const std::byte> payload);

// Read and check the chunk table of a file of `fileSize` bytes from `in` (which seeks): the
// chunks, in file order, hold the header's points, lie between the point data and the table,
// and each takes at most kMaxLazChunkBytes (laz_decoder.h). Throws FileError naming the damage.
std::vector<LazChunk> readLazChunkTable(InputStream& in, const LasHeader& header,
                                        uint32_t chunkSize, uint64_t fileSize);

}  // namespace iso::io
