// Points chunks (specs/iso-format.md, "Points chunks"): the original points of a file's scan,
// Draco-compressed, one octree cell per chunk.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "iso/format.h"

namespace iso {

class Reader;

inline constexpr uint8_t kPointsKind = static_cast<uint8_t>(ChunkKind::Points);
// Since 2.1: per-point values of a points chunk, and volume points (the same data as points
// chunks; samples of a volume, not of the surface).
inline constexpr uint8_t kValuesKind = static_cast<uint8_t>(ChunkKind::Values);
inline constexpr uint8_t kVolumePointsKind = static_cast<uint8_t>(ChunkKind::VolumePoints);
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

// Decode and check a points or volume points chunk of an open file (the rules of "Points
// chunks"). Throws iso::FileError naming the file, the chunk's offset and the problem.
PointsChunk decodePointsChunk(const Reader& reader, uint32_t id);

// The order in which a points chunk's data (encodePointsChunk(points)) gives back its points:
// order[i] is the index in `points` of the i-th decoded point. Draco's kd-tree coder reorders
// points; points alike in every attribute are interchangeable, so any of them matches.
std::vector<uint32_t> decodedPointOrder(std::span<const std::byte> data, const PointsChunk& points);

// Values chunks (since 2.1; specs/iso-format.md, "Values chunks"): one scalar per point of a points
// or volume points chunk, in the order its data gives the points, as 16-bit codes:
// value = offset + code · step; with `missing`, code 65535 (kNoValue) = no value.
inline constexpr uint32_t kValuesHeaderSize = 64;
inline constexpr size_t kMaxValueNameBytes = 32;
inline constexpr uint16_t kNoValue = 65535;
struct PointValues {
  uint32_t pointsChunk = 0;  // the chunk id whose points these values belong to
  std::string name;          // 1 to 32 bytes of UTF-8 without a zero byte
  double offset = 0.0, step = 1.0;
  bool missing = false;  // some points have no value: code kNoValue says which
  std::vector<uint16_t> codes;
  size_t size() const { return codes.size(); }
  double value(size_t i) const;  // NaN for kNoValue when `missing`
};
// The codes of `values` (non-finite: kNoValue, `missing`): offset = the smallest finite value;
// with c = 65535 codes for values (65534 when some are missing), step = 1 when every finite value
// is an integer and they span less than c (kept exactly), else the span / (c - 1) (every value
// within step / 2). Throws iso::InternalError for a name the format does not
// allow or values whose span overflows.
PointValues quantizeValues(std::string name, uint32_t pointsChunk, std::span<const double> values);
std::vector<std::byte> encodeValuesChunk(const PointValues& values);
// Decode and check a values chunk (its rules and its points chunk's count, level and key).
PointValues decodeValuesChunk(const Reader& reader, uint32_t id);

// The points chunks of a file that are subsamples (the parents of other points chunks: drawn from
// afar in place of them, and not among the file's kept points), by chunk id.
std::vector<bool> subsampleChunks(const Reader& reader);

// A stored point's frame position: the cell (level, key)'s minimum corner plus offset ·
// 2^-stepBits (exact in double for in-frame points).
std::array<double, 3> pointFramePosition(uint8_t level, uint64_t key, uint8_t stepBits,
                                         const std::array<int32_t, 3>& offset);

}  // namespace iso
