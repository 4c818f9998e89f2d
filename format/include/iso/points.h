// Points chunks (specs/iso-format.md, "Points chunks"): the original points of a file's scan,
// Draco-compressed, one octree cell per chunk.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "iso/format.h"

namespace iso {

class Reader;

inline constexpr uint8_t kPointsKind = static_cast<uint8_t>(ChunkKind::Points);
inline constexpr uint32_t kPointsHeaderSize = 8;
inline constexpr uint32_t kMaxPointsPerChunk = uint32_t{1} << 20;
inline constexpr uint8_t kMaxPointStepBits = 52;
// Along each axis a chunk's offsets differ by at most this much (Draco's kd-tree coder's limit).
inline constexpr uint32_t kMaxPointOffsetSpan = (uint32_t{1} << 31) - 1;
// Bits of the header's `attributes` byte.
inline constexpr uint8_t kPointsHaveColors = 1;
inline constexpr uint8_t kPointsHaveNormals = 2;
inline constexpr uint8_t kPointsHaveRadii = 4;  // since 2.0

// A point's splat radius as its 16-bit code (specs/iso-format.md, "Points chunks"): the radius is
// 2^(-code / 1024) frame units. Encoding rounds up (a stored radius is never smaller), clamped
// to [2^-64, 1].
uint16_t encodePointRadius(double radius);
double decodePointRadius(uint16_t code);
// The radius of a point from its chunk's density, for points without one (specs/iso-format.md,
// "Points chunks"): a surface through the cell at `level` sampled by `count` points, whose k-NN
// radius is about twice their spacing: 2 · 2^-level / √count.
double densityPointRadius(uint8_t level, uint64_t count);

// The content of one points chunk. Point i lies at the chunk cell's minimum corner plus
// offsets[i] · 2^-stepBits, in frame units.
struct PointsChunk {
  uint8_t stepBits = 0;
  std::vector<std::array<int32_t, 3>> offsets;
  // sRGB, 65535 = 1; empty: the points have none. Stored as bytes when all are 257 · (0 to 255).
  std::vector<std::array<uint16_t, 3>> colors;
  std::vector<std::array<int16_t, 3>> normals;  // snorm16 (value / 32767); empty: none
  std::vector<uint16_t> radii;  // splat radii (encodePointRadius); empty: none

  size_t size() const { return offsets.size(); }
};

// The chunk's data: its header and one Draco point cloud (kd-tree encoding at Draco's encoder
// `speed`, 0 to 10). Throws iso::InternalError for a chunk the format does not allow (no
// points, more than kMaxPointsPerChunk, attributes not one per point, stepBits too large, offsets
// spanning more than kMaxPointOffsetSpan).
std::vector<std::byte> encodePointsChunk(const PointsChunk& points, int speed = 0);

// Decode and check a points chunk of an open file (the rules of "Points chunks"). Throws
// iso::FileError naming the file, the chunk's offset and the problem.
PointsChunk decodePointsChunk(const Reader& reader, uint32_t id);

// The points chunks of a file that are subsamples (the parents of other points chunks: drawn from
// afar in place of them, and not among the file's kept points), by chunk id.
std::vector<bool> subsampleChunks(const Reader& reader);

// A stored point's frame position: the cell (level, key)'s minimum corner plus offset ·
// 2^-stepBits (exact in double for in-frame points).
std::array<double, 3> pointFramePosition(uint8_t level, uint64_t key, uint8_t stepBits,
                                         const std::array<int32_t, 3>& offset);

}  // namespace iso
