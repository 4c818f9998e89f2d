// Byte layouts of the header, attribute descriptors, chunk table entries and trailer: the one
// place that knows where each field lives (specs/iso-format.md gives the same tables).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "iso/format.h"

namespace iso::detail {

// Field offsets inside the header.
namespace hdr {
inline constexpr uint32_t kMagic = 0;
inline constexpr uint32_t kVersionMajor = 8;
inline constexpr uint32_t kVersionMinor = 10;
inline constexpr uint32_t kHeaderSize = 12;
inline constexpr uint32_t kFlags = 16;
inline constexpr uint32_t kAlignmentLog2 = 20;
inline constexpr uint32_t kMaxLevel = 21;
inline constexpr uint32_t kAttributeCount = 22;
inline constexpr uint32_t kReserved23 = 23;
inline constexpr uint32_t kFrameOrigin = 24;
inline constexpr uint32_t kFrameSize = 48;
inline constexpr uint32_t kAttributes = 56;
inline constexpr uint32_t kAttributeSize = 8;
inline constexpr uint32_t kReserved120 = 120;
inline constexpr uint32_t kChecksum = 248;
inline constexpr uint32_t kReservedFlags = 0x0000FFFFu;
}  // namespace hdr

// Field offsets inside a chunk table entry.
namespace entry {
inline constexpr uint32_t kOffset = 0;
inline constexpr uint32_t kStoredSize = 8;
inline constexpr uint32_t kRawSize = 16;
inline constexpr uint32_t kChecksum = 24;
inline constexpr uint32_t kKey = 32;
inline constexpr uint32_t kPointCount = 40;
inline constexpr uint32_t kId = 48;
inline constexpr uint32_t kParent = 52;
inline constexpr uint32_t kNodeCount = 56;
inline constexpr uint32_t kLeafCount = 60;
inline constexpr uint32_t kGeometricError = 64;
inline constexpr uint32_t kLevel = 68;
inline constexpr uint32_t kCodec = 69;
inline constexpr uint32_t kKind = 70;
inline constexpr uint32_t kReserved71 = 71;
inline constexpr uint32_t kReserved72 = 72;
}  // namespace entry

// Field offsets inside the trailer.
namespace trl {
inline constexpr uint32_t kChunkTableOffset = 0;
inline constexpr uint32_t kChunkCount = 8;
inline constexpr uint32_t kChunkEntrySize = 12;
inline constexpr uint32_t kMetadataOffset = 16;
inline constexpr uint32_t kMetadataSize = 24;
inline constexpr uint32_t kChunkTableChecksum = 32;
inline constexpr uint32_t kMetadataChecksum = 40;
inline constexpr uint32_t kChecksum = 48;
inline constexpr uint32_t kMagic = 56;
}  // namespace trl

struct Trailer {
  uint64_t chunkTableOffset = 0;
  uint32_t chunkCount = 0;
  uint32_t chunkEntrySize = kChunkEntrySize;
  uint64_t metadataOffset = 0;
  uint64_t metadataSize = 0;
  uint64_t chunkTableChecksum = 0;
  uint64_t metadataChecksum = 0;
};

// A problem found in a structure: the offset of the field inside the structure and the reason.
struct FieldProblem {
  uint32_t offset;
  std::string reason;
};

// Encode a header with its checksum. The header must be valid (headerProblem() empty).
std::array<std::byte, kHeaderSize> encodeHeader(const FileHeader& header);

// Decode a header whose magic, version, size and checksum were already checked; reports the first
// field that breaks the format's rules.
FileHeader decodeHeader(const std::byte* bytes, std::optional<FieldProblem>& problem);

// The first rule of specs/iso-format.md a header's values break, if any.
std::optional<FieldProblem> headerProblem(const FileHeader& header);

void encodeChunkEntry(const ChunkInfo& chunk, std::byte* out);

// Decode an entry; sets reservedOffset to the first non-zero reserved field, if any.
ChunkInfo decodeChunkEntry(const std::byte* bytes, std::optional<uint32_t>& reservedOffset);

std::array<std::byte, kTrailerSize> encodeTrailer(const Trailer& trailer);
Trailer decodeTrailer(const std::byte* bytes);

}  // namespace iso::detail
