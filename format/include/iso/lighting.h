// Lighting chunks (specs/iso-format.md, "Lighting chunks", since 2.2): the irradiance baked at the
// corners of one surface chunk (`iso bake`), RGB in the shared-exponent encoding RGB9E5.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "iso/format.h"
#include "iso/surface.h"

namespace iso {

class Reader;

inline constexpr uint8_t kLightingKind = static_cast<uint8_t>(ChunkKind::Lighting);
inline constexpr uint32_t kLightingHeaderSize = 16;
// The largest RGB9E5 channel value: (511 / 512) · 2^16.
inline constexpr float kMaxRgb9e5 = 65408.0f;

// RGB as one 32-bit word: three 9-bit mantissas sharing a 5-bit exponent (bias 15). Channels are
// clamped to [0, kMaxRgb9e5] (NaN to 0) and rounded to the nearest code: each channel is kept
// within 2^-9 of the largest one (half a step of its mantissa, 256 to 511), the largest within
// 2^-9 of itself.
uint32_t encodeRgb9e5(const std::array<float, 3>& rgb);
std::array<float, 3> decodeRgb9e5(uint32_t code);

// The irradiance of the leaf and level-of-detail corners of surface chunk `surfaceChunk`, in its
// corner number order (linear RGB, the viewer's light units), and the leaves' corners that have
// their own (node and corner increasing).
struct ChunkLighting {
  uint32_t surfaceChunk = 0;
  std::vector<std::array<float, 3>> leaf, lod;
  std::vector<CornerOverride> overrides;
};

std::vector<std::byte> encodeLightingChunk(const ChunkLighting& lighting);

// Decode and check lighting chunk `id`: its payload, header, surface chunk (kind and cell) and
// size. Throws iso::FileError naming the file, the chunk and the rule.
ChunkLighting decodeLightingChunk(const Reader& reader, uint32_t id);

// For every chunk id, the id of the lighting chunk of that surface chunk, or kNoParent. Reads
// the payload headers of the lighting chunks; throws iso::FileError when one names a chunk that
// is not a surface chunk or a surface chunk has two.
std::vector<uint32_t> lightingChunks(const Reader& reader);

// The same from the chunk table alone, for readers that decode a few chunks: the lighting chunk in
// each surface chunk's cell (which attachLighting checks is that chunk's). Where two lighting
// chunks share a cell, lightingChunks' answer.
std::vector<uint32_t> lightingByCell(const Reader& reader);

// Decode lighting chunk `id` into the irradiance of `chunk`, surface chunk `surfaceId`: throws
// iso::FileError when it is another surface chunk's, its corner counts are not the chunk's or an
// override's node is not one of its filled leaves.
void attachLighting(const Reader& reader, uint32_t id, uint32_t surfaceId, SurfaceChunk& chunk);

}  // namespace iso
