// Surface chunks (kind 1): the octree nodes of one cell of the file over a range of levels, with
// the attributes of their corners. Byte layout in specs/iso-format.md, "Surface chunks".
//
// The surface inside a filled leaf is the zero set of the trilinear interpolation of the signed
// distances at its 8 corners. Leaves share corners: a corner is stored once per chunk however
// many leaves use it, and the leaves find it by a numbering rule that encoder and decoder apply
// alike (layoutSurface). Internal nodes carry their own corners (level of detail).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "iso/format.h"

namespace iso {

class Reader;

inline constexpr uint8_t kSurfaceKind = 1;
inline constexpr uint32_t kSurfaceHeaderSize = 24;
inline constexpr uint32_t kNoNode = 0xFFFFFFFFu;

// Corner c of a node is at offset ((c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1) cells.
inline constexpr int kCorners = 8;

// A position on the grid of the finest level (kMaxLevel): coordinates 0 to 2^21.
struct GridPoint {
  uint32_t x = 0, y = 0, z = 0;
  bool operator==(const GridPoint&) const = default;
};

// The structure of one chunk, as stored.
struct SurfaceTopology {
  uint8_t startLevel = 0;           // level of the chunk's top nodes (its roots)
  uint8_t depth = 1;                // levels stored: startLevel to startLevel + depth - 1
  std::vector<uint64_t> rootKeys;   // keys of the roots at startLevel, strictly increasing
  std::vector<uint8_t> childMasks;  // per node, breadth-first, roots first
};

struct SurfaceNode {
  uint64_t key = 0;
  uint8_t level = 0;
  uint8_t childMask = 0;          // 0: a filled leaf; bit o: the child in octant o exists
  uint32_t firstChild = kNoNode;  // its children in this chunk (octant order), or kNoNode
  std::array<uint32_t, kCorners> corners{};  // leaf: leaf corner numbers; else LOD corner numbers
  bool isLeaf() const { return childMask == 0; }
};

// A numbered corner: where it is and the level whose node diagonal scales its distance (for leaf
// corners the coarsest leaf of the chunk that uses it; for LOD corners the node level).
struct CornerKey {
  GridPoint point;
  uint8_t level = 0;
};

struct CornerLayout {
  std::vector<SurfaceNode> nodes;      // in topology order
  std::vector<CornerKey> leafCorners;  // by corner number
  std::vector<CornerKey> lodCorners;
};

// Attribute values in float form, by corner number.
struct CornerValues {
  std::vector<float> distance;               // frame units (the frame's size is 1)
  std::vector<std::array<float, 3>> normal;  // unit; empty when the schema has none
  std::vector<std::array<float, 3>> color;   // linear RGB; empty when the schema has none
  std::vector<float> occlusion;              // empty when the schema has none
  // Baked irradiance (linear RGB; iso/lighting.h): not a schema attribute but the lighting chunk
  // of the surface chunk, when the file has one (attachLighting); else empty.
  std::vector<std::array<float, 3>> irradiance;
  size_t size() const { return distance.size(); }
};

// Nodes and corner numbering of a topology inside the chunk cell (chunkLevel, chunkKey), for a
// topology its caller made: one that breaks the format's rules is a bug (iso::InternalError
// naming the rule).
CornerLayout layoutSurface(const SurfaceTopology& topology, uint8_t chunkLevel, uint64_t chunkKey,
                           uint8_t maxLevel);
// The same for a topology read from a file: one that breaks the rules gives no layout, and
// `problem` names the rule.
std::optional<CornerLayout> tryLayoutSurface(const SurfaceTopology& topology, uint8_t chunkLevel,
                                             uint64_t chunkKey, uint8_t maxLevel,
                                             std::string& problem);

// The payload of a surface chunk. Values are quantized per the schema; their counts must match
// the layout's (iso::InternalError otherwise).
std::vector<std::byte> encodeSurfaceChunk(const SurfaceTopology& topology,
                                          const CornerLayout& layout,
                                          const std::vector<AttributeDesc>& schema,
                                          const CornerValues& leafValues,
                                          const CornerValues& lodValues);

// A value of one corner of one filled leaf that differs from its shared corner's (lighting: a
// corner between two sides of a thin wall lights each side's leaves as that side).
struct CornerOverride {
  uint32_t node = 0;  // in layout order
  uint8_t corner = 0;
  std::array<float, 3> value{};
  bool operator==(const CornerOverride&) const = default;
};

struct SurfaceChunk {
  SurfaceTopology topology;
  CornerLayout layout;
  CornerValues leafValues, lodValues;  // dequantized
  // With lighting (attachLighting): the leaves' corners whose irradiance is their own, by node
  // and corner, increasing.
  std::vector<CornerOverride> irradianceOverrides;
};

// Decode and validate surface chunk `id` of a file. Throws iso::FileError (file, the chunk's
// payload offset, reason) for any payload that breaks the format's rules.
SurfaceChunk decodeSurfaceChunk(const Reader& reader, uint32_t id);

// The diagonal of a node at level, in frame units.
inline double nodeDiagonal(uint8_t level) { return std::sqrt(3.0) * std::ldexp(1.0, -level); }

// The signed distance that survives quantization: what a reader decodes for value f at a corner
// scaled by level (the writer uses it to snap corners on dequantized values).
float roundTripDistance(float f, uint8_t level, const AttributeDesc& distance);

// Weights of the 8 corners of a trilinear cell at local coordinates u in [0, 1]^3, and their
// derivatives along each axis.
std::array<double, 8> trilinearWeights(const std::array<double, 3>& u);
std::array<std::array<double, 8>, 3> trilinearWeightGradients(const std::array<double, 3>& u);

// Grid position of corner c of the node (level, key).
GridPoint cornerPoint(uint8_t level, uint64_t key, int corner);

// The trilinear interpolation of corner values v (corner c at x = bit 0, y = bit 1, z = bit 2 of c)
// at local coordinates u in [0, 1]^3, and its gradient in local units when asked. Exact at the
// corners and on the faces: a face's value depends only on the face's 4 corners.
inline double trilinear(const std::array<double, 8>& v, const std::array<double, 3>& u,
                        std::array<double, 3>* gradient = nullptr) {
  const auto lerp = [](double a, double b, double t) { return (1.0 - t) * a + t * b; };
  const double a00 = lerp(v[0], v[1], u[0]), a10 = lerp(v[2], v[3], u[0]);
  const double a01 = lerp(v[4], v[5], u[0]), a11 = lerp(v[6], v[7], u[0]);
  const double b0 = lerp(a00, a10, u[1]), b1 = lerp(a01, a11, u[1]);
  if (gradient) {
    const double dy0 = lerp(v[1] - v[0], v[3] - v[2], u[1]);
    const double dy1 = lerp(v[5] - v[4], v[7] - v[6], u[1]);
    *gradient = {lerp(dy0, dy1, u[2]), lerp(a10 - a00, a11 - a01, u[2]), b1 - b0};
  }
  return lerp(b0, b1, u[2]);
}

namespace detail {
// Spread the low 21 bits of v so that bit j moves to bit 3j, and back.
inline uint64_t spreadBits(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}
inline uint32_t compactBits(uint64_t v) {
  v &= 0x1249249249249249ull;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ull;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00full;
  v = (v ^ (v >> 8)) & 0x1f0000ff0000ffull;
  v = (v ^ (v >> 16)) & 0x1f00000000ffffull;
  v = (v ^ (v >> 32)) & 0x1fffffull;
  return static_cast<uint32_t>(v);
}
}  // namespace detail

// Cell coordinates of a Morton key and back.
inline std::array<uint32_t, 3> mortonDecode(uint64_t key) {
  return {detail::compactBits(key), detail::compactBits(key >> 1), detail::compactBits(key >> 2)};
}
inline uint64_t mortonEncode(uint32_t x, uint32_t y, uint32_t z) {
  return detail::spreadBits(x) | detail::spreadBits(y) << 1 | detail::spreadBits(z) << 2;
}

}  // namespace iso
