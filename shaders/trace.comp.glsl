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
// The two passes of a wavefront frame (kPass 1 and 2): the camera rays' hits, three vec4s each
// (t, side, occlusion, pixel index; normal; color), and the queue's words: the count of hits, the
// indirect dispatch of the second pass (x, y, z workgroups), and the wave's first tile.
layout(std430, binding = 5) buffer Hits { vec4 hits[]; };
layout(std430, binding = 6) buffer Queue { uint queue[]; };
// Where each tile's camera rays start (cone.h), written by the cone pass (kPass 3) before the
// frame's other passes, when tile cones are on.
layout(std430, binding = 7) buffer Starts { float starts[]; };
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
// 0: each invocation draws its pixel whole (one kernel). A wavefront frame (one sample a pixel,
// no secondary rays) runs two, a wave of tiles at a time: 1 traces the camera rays and appends
// their hits to a queue, 2 shades the queued hits with their shadow rays, the hits side by side in
// the SIMD lanes. 3 traces the tiles' cones first, a tile an invocation.
layout(constant_id = 3) const uint kPass = 0u;

#include "trace.h"

// The workgroup's tile: tileWidth × tileHeight pixels (as wide as high, or twice as wide), tiles
// row by row. Returns the tile's first pixel; `size` is its width and height.
uvec2 tileOrigin(uint tile, out uvec2 size) {
  uint tileWidth = 1u << uint((findMSB(gl_WorkGroupSize.x) + 1) / 2);
  uint tileHeight = gl_WorkGroupSize.x / tileWidth;
  uint tilesX = (P.image.x + tileWidth - 1u) / tileWidth;
  size = uvec2(tileWidth, tileHeight);
  return uvec2((tile % tilesX) * tileWidth, (tile / tilesX) * tileHeight);
}

// The pixel of this invocation in the tile: Z-order, x from the even bits of its index, y from
// the odd.
uvec2 tilePixel(uvec2 origin) {
  uint i = gl_LocalInvocationIndex;
  uint lx = 0u, ly = 0u;
  for (uint b = 0u; b < 5u; ++b) {
    lx |= ((i >> (2u * b)) & 1u) << b;
    ly |= ((i >> (2u * b + 1u)) & 1u) << b;
  }
  return origin + uvec2(lx, ly);
}

// Pass 3: the cone of this invocation's tile.
void traceCones() {
  uvec2 size;
  uvec2 origin = tileOrigin(gl_GlobalInvocationID.x, size);
  if (origin.y >= P.image.y) return;
  uvec2 end = min(origin + size, uvec2(P.image.x, P.image.y));
  starts[gl_GlobalInvocationID.x] = tileStart(origin.x, origin.y, end.x, end.y);
}

// Where the camera rays of a tile start.
float tileRaysStart(uint tile) {
  return (P.options.x & kOptionTileCones) != 0u ? starts[tile] : 0.0f;
}

void countRays(uvec3 rays) {
  if (rays.x != 0u) atomicAdd(feedback[kFeedbackPrimaryRays], rays.x);
  if (rays.y != 0u) atomicAdd(feedback[kFeedbackShadowRays], rays.y);
  if (rays.z != 0u) atomicAdd(feedback[kFeedbackSecondaryRays], rays.z);
}

shared uint groupHits;
shared uint groupFirst;

// Pass 1: the camera ray of each pixel; a miss writes the background, a hit is appended to the
// queue (one global atomic a workgroup) for pass 2.
void traceCameraRays() {
  uvec2 size;
  uint tile = queue[4] + gl_WorkGroupID.x;
  uvec2 origin = tileOrigin(tile, size);
  uvec2 xy = tilePixel(origin);
  float start = tileRaysStart(tile);
  bool inside = xy.x < P.image.x && xy.y < P.image.y;
  if (gl_LocalInvocationIndex == 0u) groupHits = 0u;
  barrier();
  Hit hit;
  bool found = false;
  uint slot = 0u;
  if (inside) {
    vec3 eye = vec3(P.eye.x, P.eye.y, P.eye.z);
    vec3 d = cameraDirection(xy.x, xy.y, 0.5f, 0.5f);
    bool hideBack = (P.options.x & kOptionBackHide) != 0u;
    found = intersect(eye, d, start, 1e30f, hideBack ? 1.0f : 0.0f, hideBack, 0.0f,
                      (P.options.x & kOptionRequests) != 0u, hit);
    if (found)
      slot = atomicAdd(groupHits, 1u);
    else
      pixels[xy.y * P.image.x + xy.x] = packPixel(background(d));
  }
  barrier();
  if (gl_LocalInvocationIndex == 0u && groupHits > 0u) {
    groupFirst = atomicAdd(queue[0], groupHits);
    atomicMax(queue[1], (groupFirst + groupHits + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x);
  }
  barrier();
  if (found) {
    uint at = 3u * (groupFirst + slot);
    hits[at] = vec4(hit.t, hit.from, hit.occlusion, uintBitsToFloat(xy.y * P.image.x + xy.x));
    hits[at + 1u] = vec4(hit.normal, 0.0f);
    hits[at + 2u] = vec4(hit.color, 0.0f);
  }
  if (inside) atomicAdd(feedback[kFeedbackPrimaryRays], 1u);
}

// Pass 2: the queued hits, shaded as the one kernel shades a camera ray's hit.
void shadeHits() {
  uint index = gl_GlobalInvocationID.x;
  if (index >= queue[0]) return;
  vec4 a = hits[3u * index];
  uint pixel = floatBitsToUint(a.w);
  uint x = pixel % P.image.x, y = pixel / P.image.x;
  Hit hit;
  hit.t = a.x;
  hit.from = a.y;
  hit.occlusion = a.z;
  hit.normal = hits[3u * index + 1u].xyz;
  hit.color = hits[3u * index + 2u].xyz;
  vec3 eye = vec3(P.eye.x, P.eye.y, P.eye.z);
  vec3 d = cameraDirection(x, y, 0.5f, 0.5f);
  vec3 p = eye + d * hit.t;
  hit.normal = hit.from * hit.normal;  // facing the ray
  uint rng = pixelSeed(x, y);
  uvec3 rays = uvec3(0u);
  pixels[pixel] = packPixel(localFraction() * shadeOutside(p, d, hit, hit.t, rng, rays));
  countRays(rays);
}

void main() {
  if (kPass == 1u) {
    traceCameraRays();
    return;
  }
  if (kPass == 2u) {
    shadeHits();
    return;
  }
  if (kPass == 3u) {
    traceCones();
    return;
  }
  uvec2 size;
  uvec2 origin = tileOrigin(gl_WorkGroupID.x, size);
  uvec2 xy = tilePixel(origin);
  float start = tileRaysStart(gl_WorkGroupID.x);
  if (xy.x >= P.image.x || xy.y >= P.image.y) return;
  uvec3 rays = uvec3(0u);
  pixels[xy.y * P.image.x + xy.x] = renderPixel(xy.x, xy.y, start, rays);
  countRays(rays);
}
