// The rules of the chunk table (specs/iso-format.md, "Chunk table", "Points chunks", "Lighting
// chunks"), as the reader checks them when it opens a file and the writer before it writes.
#include "chunk_rules.h"

#include <cmath>
#include <string>
#include <vector>

#include "iso/lighting.h"
#include "iso/points.h"
#include "iso/surface.h"

namespace iso::detail {
namespace {

// The rule of "Points chunks" (and, since 2.1, of "Volume points" and "Values chunks") that the
// entry of such a chunk breaks.
std::optional<FieldProblem> pointsEntryProblem(const ChunkInfo& c) {
  const std::string what(c.kind == kValuesKind ? "a values chunk" : "a points chunk");
  if (c.pointCount == 0 || c.pointCount > kMaxPointsPerChunk)
    return FieldProblem{entry::kPointCount, what + " holds 1 to " +
                                                std::to_string(kMaxPointsPerChunk) +
                                                " points, not " + std::to_string(c.pointCount)};
  if (c.nodeCount != 0) return FieldProblem{entry::kNodeCount, what + " has nodes"};
  if (c.leafCount != 0) return FieldProblem{entry::kLeafCount, what + " has leaves"};
  if (c.kind != kPointsKind && c.parent != kNoParent)
    return FieldProblem{entry::kParent, what + " of this kind has no parent"};
  return std::nullopt;
}

// The rule of "Lighting chunks" (since 2.2) that the entry of such a chunk breaks.
std::optional<FieldProblem> lightingEntryProblem(const ChunkInfo& c) {
  if (c.pointCount != 0) return FieldProblem{entry::kPointCount, "a lighting chunk has points"};
  if (c.nodeCount != 0) return FieldProblem{entry::kNodeCount, "a lighting chunk has nodes"};
  if (c.leafCount != 0) return FieldProblem{entry::kLeafCount, "a lighting chunk has leaves"};
  if (c.parent != kNoParent) return FieldProblem{entry::kParent, "a lighting chunk has no parent"};
  if (c.geometricError != 0.0f)
    return FieldProblem{entry::kGeometricError, "a lighting chunk has no geometric error"};
  return std::nullopt;
}

}  // namespace

std::optional<FieldProblem> chunkEntryProblem(const ChunkInfo& c, uint32_t index, uint8_t maxLevel,
                                              uint64_t expectedOffset, uint64_t payloadsEnd) {
  if (c.id != index) return FieldProblem{entry::kId, "id is " + std::to_string(c.id)};
  if (c.codec != Codec::Raw && c.codec != Codec::Zstd)
    return FieldProblem{entry::kCodec, "unknown codec " + std::to_string(int(c.codec))};
  if (c.level > maxLevel)
    return FieldProblem{entry::kLevel, "level " + std::to_string(c.level) +
                                           " is above the file's maximum level " +
                                           std::to_string(maxLevel)};
  if (!isValidKey(c.level, c.key)) return FieldProblem{entry::kKey, "key does not fit its level"};
  if (c.rawSize > kMaxChunkRawSize)
    return FieldProblem{entry::kRawSize, "raw size is over the limit of 2^30 bytes"};
  if (c.codec == Codec::Raw && c.storedSize != c.rawSize)
    return FieldProblem{entry::kStoredSize, "raw chunk with stored size != raw size"};
  if (c.codec == Codec::Zstd && c.storedSize == 0)
    return FieldProblem{entry::kStoredSize, "zstd chunk with no stored bytes"};
  if (c.codec == Codec::Zstd && (c.rawSize + kMaxZstdRatio - 1) / kMaxZstdRatio > c.storedSize)
    return FieldProblem{entry::kRawSize,
                        "raw size is more than 32768 times the stored size (more than a zstd "
                        "frame of that size decodes to)"};
  if (c.offset != expectedOffset)
    return FieldProblem{entry::kOffset, "payload offset " + std::to_string(c.offset) +
                                            " is not where the layout puts it (" +
                                            std::to_string(expectedOffset) + ")"};
  if (c.offset > payloadsEnd || c.storedSize > payloadsEnd - c.offset)
    return FieldProblem{entry::kStoredSize, "payload runs into the chunk table"};
  if (!std::isfinite(c.geometricError) || c.geometricError < 0.0f)
    return FieldProblem{entry::kGeometricError, "geometric error is negative or not finite"};
  if (c.kind == kPointsKind || c.kind == kVolumePointsKind || c.kind == kValuesKind)
    return pointsEntryProblem(c);
  if (c.kind == kLightingKind) return lightingEntryProblem(c);
  return std::nullopt;
}

std::optional<ChunkProblem> parentProblem(std::span<const ChunkInfo> chunks) {
  for (const ChunkInfo& c : chunks) {
    if (c.parent == kNoParent) continue;
    const std::string who = "parent " + std::to_string(c.parent);
    if (c.parent >= chunks.size())
      return ChunkProblem{c.id, {entry::kParent, who + " does not exist"}};
    const ChunkInfo& p = chunks[c.parent];
    if (p.level >= c.level || !cellContains(p.level, p.key, c.level, c.key))
      return ChunkProblem{c.id, {entry::kParent, who + " is not a coarser cell containing it"}};
    if (c.kind == kPointsKind && p.kind != kPointsKind)
      return ChunkProblem{
          c.id,
          {entry::kParent,
           who + " is not a points chunk (a points chunk's parent is its subsample)"}};
  }
  return std::nullopt;
}

// Those whose parent is a surface chunk count together at most their parent's points (their cells
// are disjoint parts of its cells); the others count together at most kMaxPointCount. Every sum
// over surface chunks then stays below 2^58.
std::optional<ChunkProblem> surfacePointCountProblem(std::span<const ChunkInfo> chunks) {
  std::vector<uint64_t> children(chunks.size(), 0);
  uint64_t tops = 0;
  for (const ChunkInfo& c : chunks) {
    if (c.kind != kSurfaceKind) continue;
    const std::string who = "point count " + std::to_string(c.pointCount);
    if (c.parent != kNoParent && chunks[c.parent].kind == kSurfaceKind) {
      const ChunkInfo& p = chunks[c.parent];
      if (c.pointCount > p.pointCount - children[p.id])
        return ChunkProblem{c.id,
                            {entry::kPointCount, who + " and those of the other chunks of parent " +
                                                     std::to_string(p.id) + " exceed its " +
                                                     std::to_string(p.pointCount)}};
      children[p.id] += c.pointCount;
    } else {
      if (c.pointCount > kMaxPointCount - tops)
        return ChunkProblem{
            c.id,
            {entry::kPointCount, who + " brings the points of the top surface chunks over 2^53"}};
      tops += c.pointCount;
    }
  }
  return std::nullopt;
}

}  // namespace iso::detail
