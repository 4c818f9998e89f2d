// Encoding and decoding of the fixed-size structures (specs/iso-format.md).
#include "layout.h"

#include <cmath>
#include <cstring>

#include "bytes.h"

namespace iso::detail {
namespace {

bool isZero(const std::byte* bytes, size_t size) {
  for (size_t i = 0; i < size; ++i)
    if (bytes[i] != std::byte{0}) return false;
  return true;
}

}  // namespace

std::optional<FieldProblem> headerProblem(const FileHeader& h) {
  if (h.flags & hdr::kReservedFlags) return FieldProblem{hdr::kFlags, "reserved flag bits are set"};
  if (h.payloadAlignmentLog2 < kMinPayloadAlignmentLog2 ||
      h.payloadAlignmentLog2 > kMaxPayloadAlignmentLog2)
    return FieldProblem{hdr::kAlignmentLog2, "payload alignment must be 2^3 to 2^16 bytes"};
  if (h.maxLevel > kMaxLevel) return FieldProblem{hdr::kMaxLevel, "maximum level is over 21"};
  if (const std::optional<FrameProblem> problem = frameProblem(h.frame))
    return FieldProblem{
        problem->field < 3 ? hdr::kFrameOrigin + 8u * uint32_t(problem->field) : hdr::kFrameSize,
        std::string(problem->reason)};
  if (std::string_view problem = attributeSchemaProblem(h.attributes); !problem.empty())
    return FieldProblem{hdr::kAttributes, std::string(problem)};
  return std::nullopt;
}

std::array<std::byte, kHeaderSize> encodeHeader(const FileHeader& h) {
  std::array<std::byte, kHeaderSize> out{};
  std::byte* p = out.data();
  std::memcpy(p + hdr::kMagic, kHeaderMagic.data(), kHeaderMagic.size());
  storeLE<uint16_t>(p + hdr::kVersionMajor, h.versionMajor);
  storeLE<uint16_t>(p + hdr::kVersionMinor, h.versionMinor);
  storeLE<uint32_t>(p + hdr::kHeaderSize, kHeaderSize);
  storeLE<uint32_t>(p + hdr::kFlags, h.flags);
  storeLE<uint8_t>(p + hdr::kAlignmentLog2, h.payloadAlignmentLog2);
  storeLE<uint8_t>(p + hdr::kMaxLevel, h.maxLevel);
  storeLE<uint8_t>(p + hdr::kAttributeCount, static_cast<uint8_t>(h.attributes.size()));
  for (int axis = 0; axis < 3; ++axis)
    storeLE<double>(p + hdr::kFrameOrigin + 8 * axis, h.frame.origin[axis]);
  storeLE<double>(p + hdr::kFrameSize, h.frame.size);
  for (size_t i = 0; i < h.attributes.size(); ++i) {
    std::byte* a = p + hdr::kAttributes + hdr::kAttributeSize * i;
    storeLE<uint8_t>(a + 0, static_cast<uint8_t>(h.attributes[i].semantic));
    storeLE<uint8_t>(a + 1, static_cast<uint8_t>(h.attributes[i].encoding));
    storeLE<uint8_t>(a + 2, h.attributes[i].components);
    storeLE<float>(a + 4, h.attributes[i].scale);
  }
  storeLE<uint64_t>(p + hdr::kChecksum, checksum({p, hdr::kChecksum}));
  return out;
}

FileHeader decodeHeader(const std::byte* p, std::optional<FieldProblem>& problem) {
  FileHeader h;
  h.versionMajor = loadLE<uint16_t>(p + hdr::kVersionMajor);
  h.versionMinor = loadLE<uint16_t>(p + hdr::kVersionMinor);
  h.flags = loadLE<uint32_t>(p + hdr::kFlags);
  h.payloadAlignmentLog2 = loadLE<uint8_t>(p + hdr::kAlignmentLog2);
  h.maxLevel = loadLE<uint8_t>(p + hdr::kMaxLevel);
  const uint8_t attributeCount = loadLE<uint8_t>(p + hdr::kAttributeCount);
  for (int axis = 0; axis < 3; ++axis)
    h.frame.origin[axis] = loadLE<double>(p + hdr::kFrameOrigin + 8 * axis);
  h.frame.size = loadLE<double>(p + hdr::kFrameSize);

  problem.reset();
  if (loadLE<uint8_t>(p + hdr::kReserved23) != 0) {
    problem = FieldProblem{hdr::kReserved23, "reserved header byte is not zero"};
    return h;
  }
  if (!isZero(p + hdr::kReserved120, hdr::kChecksum - hdr::kReserved120)) {
    problem = FieldProblem{hdr::kReserved120, "reserved header bytes are not zero"};
    return h;
  }
  if (attributeCount == 0 || attributeCount > kMaxAttributes) {
    problem = FieldProblem{hdr::kAttributeCount, "attribute count must be 1 to 8"};
    return h;
  }
  h.attributes.clear();
  for (uint32_t i = 0; i < kMaxAttributes; ++i) {
    const std::byte* a = p + hdr::kAttributes + hdr::kAttributeSize * i;
    if (i >= attributeCount) {
      if (!isZero(a, hdr::kAttributeSize)) {
        problem = FieldProblem{hdr::kAttributes + hdr::kAttributeSize * i,
                               "unused attribute entry is not zero"};
        return h;
      }
      continue;
    }
    if (loadLE<uint8_t>(a + 3) != 0) {
      problem = FieldProblem{hdr::kAttributes + hdr::kAttributeSize * i + 3,
                             "reserved attribute byte is not zero"};
      return h;
    }
    h.attributes.push_back({static_cast<Semantic>(loadLE<uint8_t>(a + 0)),
                            static_cast<Encoding>(loadLE<uint8_t>(a + 1)), loadLE<uint8_t>(a + 2),
                            loadLE<float>(a + 4)});
  }
  problem = headerProblem(h);
  return h;
}

void encodeChunkEntry(const ChunkInfo& c, std::byte* p) {
  std::memset(p, 0, kChunkEntrySize);
  storeLE<uint64_t>(p + entry::kOffset, c.offset);
  storeLE<uint64_t>(p + entry::kStoredSize, c.storedSize);
  storeLE<uint64_t>(p + entry::kRawSize, c.rawSize);
  storeLE<uint64_t>(p + entry::kChecksum, c.checksum);
  storeLE<uint64_t>(p + entry::kKey, c.key);
  storeLE<uint64_t>(p + entry::kPointCount, c.pointCount);
  storeLE<uint32_t>(p + entry::kId, c.id);
  storeLE<uint32_t>(p + entry::kParent, c.parent);
  storeLE<uint32_t>(p + entry::kNodeCount, c.nodeCount);
  storeLE<uint32_t>(p + entry::kLeafCount, c.leafCount);
  storeLE<float>(p + entry::kGeometricError, c.geometricError);
  storeLE<uint8_t>(p + entry::kLevel, c.level);
  storeLE<uint8_t>(p + entry::kCodec, static_cast<uint8_t>(c.codec));
  storeLE<uint8_t>(p + entry::kKind, c.kind);
}

ChunkInfo decodeChunkEntry(const std::byte* p, std::optional<uint32_t>& reservedOffset) {
  ChunkInfo c;
  c.offset = loadLE<uint64_t>(p + entry::kOffset);
  c.storedSize = loadLE<uint64_t>(p + entry::kStoredSize);
  c.rawSize = loadLE<uint64_t>(p + entry::kRawSize);
  c.checksum = loadLE<uint64_t>(p + entry::kChecksum);
  c.key = loadLE<uint64_t>(p + entry::kKey);
  c.pointCount = loadLE<uint64_t>(p + entry::kPointCount);
  c.id = loadLE<uint32_t>(p + entry::kId);
  c.parent = loadLE<uint32_t>(p + entry::kParent);
  c.nodeCount = loadLE<uint32_t>(p + entry::kNodeCount);
  c.leafCount = loadLE<uint32_t>(p + entry::kLeafCount);
  c.geometricError = loadLE<float>(p + entry::kGeometricError);
  c.level = loadLE<uint8_t>(p + entry::kLevel);
  c.codec = static_cast<Codec>(loadLE<uint8_t>(p + entry::kCodec));
  c.kind = loadLE<uint8_t>(p + entry::kKind);
  reservedOffset.reset();
  if (loadLE<uint8_t>(p + entry::kReserved71) != 0)
    reservedOffset = entry::kReserved71;
  else if (loadLE<uint64_t>(p + entry::kReserved72) != 0)
    reservedOffset = entry::kReserved72;
  return c;
}

std::array<std::byte, kTrailerSize> encodeTrailer(const Trailer& t) {
  std::array<std::byte, kTrailerSize> out{};
  std::byte* p = out.data();
  storeLE<uint64_t>(p + trl::kChunkTableOffset, t.chunkTableOffset);
  storeLE<uint32_t>(p + trl::kChunkCount, t.chunkCount);
  storeLE<uint32_t>(p + trl::kChunkEntrySize, t.chunkEntrySize);
  storeLE<uint64_t>(p + trl::kMetadataOffset, t.metadataOffset);
  storeLE<uint64_t>(p + trl::kMetadataSize, t.metadataSize);
  storeLE<uint64_t>(p + trl::kChunkTableChecksum, t.chunkTableChecksum);
  storeLE<uint64_t>(p + trl::kMetadataChecksum, t.metadataChecksum);
  storeLE<uint64_t>(p + trl::kChecksum, checksum({p, trl::kChecksum}));
  std::memcpy(p + trl::kMagic, kTrailerMagic.data(), kTrailerMagic.size());
  return out;
}

Trailer decodeTrailer(const std::byte* p) {
  Trailer t;
  t.chunkTableOffset = loadLE<uint64_t>(p + trl::kChunkTableOffset);
  t.chunkCount = loadLE<uint32_t>(p + trl::kChunkCount);
  t.chunkEntrySize = loadLE<uint32_t>(p + trl::kChunkEntrySize);
  t.metadataOffset = loadLE<uint64_t>(p + trl::kMetadataOffset);
  t.metadataSize = loadLE<uint64_t>(p + trl::kMetadataSize);
  t.chunkTableChecksum = loadLE<uint64_t>(p + trl::kChunkTableChecksum);
  t.metadataChecksum = loadLE<uint64_t>(p + trl::kMetadataChecksum);
  return t;
}

}  // namespace iso::detail
