// The viewer's compute shader: one invocation per pixel, 8×8 tiles visited in Z-order, tracing
// the octree in the page pool with the shared tracer (trace.h). Layouts in shared.h and
// specs/viewer.md.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

#define ISO_INOUT(T) inout T
#define ISO_PRECISE precise
#include "shared.h"

// The workgroup's size (a power of two, 8 to 1024): a tile of pixels visited in Z-order.
layout(local_size_x_id = 2) in;

layout(std140, binding = 0) uniform Frame { FrameParams P; };
layout(std430, binding = 1) readonly buffer Chunks { ChunkEntry chunks[]; };
layout(std430, binding = 2) buffer Feedback { uint feedback[]; };
layout(std430, binding = 3) writeonly buffer Image { uint pixels[]; };
layout(std430, binding = 4) readonly buffer Environment { uint environment[]; };
// The page pool's buffers, by device address (no descriptor, so no 128 MiB range limit). A blob
// lies in one buffer: its words are read from its base address.
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer PoolWords {
  uint words[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer PoolPairs {
  uvec2 pairs[];
};

#define ISO_ADDRESS uint64_t

uint64_t blobBase(uint firstPage) {
  uint word = firstPage * kPageWords;
  uint which = word >> P.pool.x;
  uvec4 pair = P.poolAddress[which >> 1u];
  uvec2 address = (which & 1u) == 0u ? uvec2(pair.x, pair.y) : uvec2(pair.z, pair.w);
  return packUint2x32(address) + uint64_t(word & ((1u << P.pool.x) - 1u)) * 4ul;
}

uint blobWord(uint64_t base, uint word) { return PoolWords(base).words[word]; }

uvec2 blobPair(uint64_t base, uint word) { return PoolPairs(base).pairs[word >> 1u]; }

uvec4 chunkState(uint chunk) { return chunks[chunk].state; }

void requestChunk(uint chunk) {
  uint at = kFeedbackHeaderWords + chunk;
  if (feedback[at] != P.image.w) feedback[at] = P.image.w;
}

void useChunk(uint chunk) {
  uint at = kFeedbackHeaderWords + P.options.w + chunk;
  if (feedback[at] != P.image.w) feedback[at] = P.image.w;
}

vec3 environmentTexel(uint x, uint y) {
  uint at = 2u * (y * P.pool.z + x);
  vec2 rg = unpackHalf2x16(environment[at]);
  vec2 ba = unpackHalf2x16(environment[at + 1u]);
  return vec3(rg.x, rg.y, ba.x);
}

vec3 fusedMultiplyAdd(vec3 a, vec3 b, vec3 c) { return fma(a, b, c); }

// The record layout is fixed for a file: a constant when the pipeline is made, so that the
// branch on it is compiled away (as a uniform branch it cost lavapipe a fifth of its speed).
layout(constant_id = 0) const bool kFloatDistances = false;
bool floatDistances() { return kFloatDistances; }
layout(constant_id = 1) const bool kFlatTraversal = false;
bool flatTraversal() { return kFlatTraversal; }

#include "trace.h"

void main() {
  // A tile of tileWidth × tileHeight pixels (as wide as high, or twice as wide), tiles row by row.
  uint tileWidth = 1u << uint((findMSB(gl_WorkGroupSize.x) + 1) / 2);
  uint tileHeight = gl_WorkGroupSize.x / tileWidth;
  uint tilesX = (P.image.x + tileWidth - 1u) / tileWidth;
  uint tile = gl_WorkGroupID.x;
  uint i = gl_LocalInvocationIndex;  // Z-order inside the tile: x from even bits, y from odd
  uint lx = 0u, ly = 0u;
  for (uint b = 0u; b < 5u; ++b) {
    lx |= ((i >> (2u * b)) & 1u) << b;
    ly |= ((i >> (2u * b + 1u)) & 1u) << b;
  }
  uint x = (tile % tilesX) * tileWidth + lx;
  uint y = (tile / tilesX) * tileHeight + ly;
  if (x >= P.image.x || y >= P.image.y) return;
  uvec3 rays = uvec3(0u);
  pixels[y * P.image.x + x] = renderPixel(x, y, rays);
  atomicAdd(feedback[kFeedbackPrimaryRays], rays.x);
  if (rays.y != 0u) atomicAdd(feedback[kFeedbackShadowRays], rays.y);
  if (rays.z != 0u) atomicAdd(feedback[kFeedbackSecondaryRays], rays.z);
}
