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
// The passes of a wavefront frame (kPass 1, 2 and 4): the hits to shade, four vec4s each (t,
// side, occlusion, pixel index; normal, path index; color, depth: 0 for a camera ray's hit; the
// baked irradiance and whether the hit has it), and
// the queue's words: 0 the count of hits, 1-3 the indirect dispatch of the shading pass (x, y, z
// workgroups), 4 the wave's first tile, 5 the count of pending mirror rays, 8-10 the indirect
// dispatch of the pass that traces them.
layout(std430, binding = 5) buffer Hits { vec4 hits[]; };
layout(std430, binding = 6) buffer Queue { uint queue[]; };
// Where each tile's camera rays start (cone.h), written by the cone pass (kPass 3) before the
// frame's other passes, when tile cones are on.
layout(std430, binding = 7) buffer Starts { float starts[]; };
// The paths of a wave's pixels whose hits reflect a mirror ray (binding 8), four vec4s each: the
// color so far, the random state; the ray's weight, the path length before it; its origin, its
// side and depth (side + 1 | depth << 2, as bits); its direction, the pixel's index. Binding 9:
// the paths whose mirror ray waits to be traced.
layout(std430, binding = 8) buffer Paths { vec4 paths[]; };
layout(std430, binding = 9) buffer Pending { uint pending[]; };
// The caustic map (shared.h, kCausticCells), summed by the photon pass (kPass 5) in the frames
// that recompute it, read by shading.
layout(std430, binding = 10) buffer Caustics { uint causticMap[]; };
// A point set surface in the scene (kOptionPss; seed 001): its parameters (binding 11, the
// grid's, the fit's and the volume's parts of PssParams, in frame units) and its buffers and its
// volume's (bindings 12 to 22, pss_buffers.h).
layout(std430, binding = 11) readonly buffer PssObject { PssParams Q; };
#define ISO_PSS_BINDING 12
#include "pss_buffers.h"
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

uint causticWord(uint word) { return causticMap[word]; }

void depositCaustic(uint word, uint value) { atomicAdd(causticMap[word], value); }

// The record layout is fixed for a file: a constant when the pipeline is made, so that the
// branch on it is compiled away (as a uniform branch it cost lavapipe a fifth of its speed).
layout(constant_id = 0) const bool kFloatDistances = false;
bool floatDistances() { return kFloatDistances; }
layout(constant_id = 1) const bool kFlatTraversal = false;
bool flatTraversal() { return kFlatTraversal; }
// 0: each invocation draws its pixel whole (one kernel). A wavefront frame (one sample a pixel,
// no secondary rays) runs two, a wave of tiles at a time: 1 traces the camera rays and appends
// their hits to a queue, 2 shades the queued hits with their shadow rays, the hits side by side in
// the SIMD lanes. 3 traces the tiles' cones first, a tile an invocation. In a frame whose hits
// reflect mirror rays (and nothing refracts), 2 also queues those rays, 4 traces them and queues
// their hits for 2, bounce after bounce. 5 traces the caustic photons, before the others, in the
// frames that recompute the caustic map.
layout(constant_id = 3) const uint kPass = 0u;
// Whether the kernel meets splats at all (kOptionSplats): the surface-only kernels are made
// without the splat code (compiled in, it cost lavapipe a third of its speed on the surface).
layout(constant_id = 4) const bool kSplats = false;
bool splatsCompiled() { return kSplats; }
// Whether the kernel meets a point set surface at all (kOptionPss), like kSplats.
layout(constant_id = 5) const bool kPss = false;
bool pssCompiled() { return kPss; }
float lodPixels() { return kPass == 5u ? -1.0f : P.lod.x; }

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
    found = traceScene(eye, d, start, 1e30f, hideBack ? 1.0f : 0.0f, hideBack, 0.0f,
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
    uint at = 4u * (groupFirst + slot);
    uint path = (tile - queue[4]) * gl_WorkGroupSize.x + gl_LocalInvocationIndex;
    hits[at] = vec4(hit.t, hit.from, hit.occlusion, uintBitsToFloat(xy.y * P.image.x + xy.x));
    hits[at + 1u] = vec4(hit.normal, uintBitsToFloat(path));
    hits[at + 2u] = vec4(hit.color, 0.0f);
    hits[at + 3u] = hit.irradiance;
  }
  if (inside) atomicAdd(feedback[kFeedbackPrimaryRays], 1u);
}

// Pass 2: the queued hits, shaded as the one kernel shades a hit outside transparent objects
// (radiance in shade.h, the same statements in the same order): a camera ray's from its pixel, a
// mirror ray's from its path. A hit that reflects a mirror ray keeps its path and queues the ray;
// the others write their pixel.
void shadeHits() {
  uint index = gl_GlobalInvocationID.x;
  if (index >= queue[0]) return;
  vec4 a = hits[4u * index];
  vec4 b = hits[4u * index + 1u];
  vec4 c = hits[4u * index + 2u];
  uint pixel = floatBitsToUint(a.w);
  uint path = floatBitsToUint(b.w);
  uint depth = floatBitsToUint(c.w);
  Hit hit;
  hit.t = a.x;
  hit.from = a.y;
  hit.occlusion = a.z;
  hit.normal = b.xyz;
  hit.color = c.xyz;
  hit.irradiance = hits[4u * index + 3u];
  vec3 origin = vec3(P.eye.x, P.eye.y, P.eye.z);
  vec3 direction;
  vec3 weight = vec3(1.0f);
  vec3 color = vec3(0.0f);
  float before = 0.0f;
  uint rng;
  if (depth == 0u) {
    uint x = pixel % P.image.x, y = pixel / P.image.x;
    direction = cameraDirection(x, y, 0.5f, 0.5f);
    rng = pixelSeed(x, y);
  } else {
    vec4 p0 = paths[4u * path];
    vec4 p1 = paths[4u * path + 1u];
    color = p0.xyz;
    rng = floatBitsToUint(p0.w);
    weight = p1.xyz;
    before = p1.w;
    origin = paths[4u * path + 2u].xyz;
    direction = paths[4u * path + 3u].xyz;
  }
  vec3 p = origin + direction * hit.t;
  vec3 n = hit.from * hit.normal;  // facing the ray
  hit.normal = n;
  float distance = before + hit.t;
  uvec3 rays = uvec3(0u);
  color += weight * localFraction(hit) * shadeOutside(p, direction, hit, distance, rng, rays);
  float mirror = hitReflectivity(hit);
  if (depth < P.options.y && mirror > 0.0f) {
    paths[4u * path] = vec4(color, uintBitsToFloat(rng));
    paths[4u * path + 1u] = vec4(weight * mirror, distance);
    uint state = uint(hit.from + 1.0f) | ((depth + 1u) << 2u);
    paths[4u * path + 2u] = vec4(p + n * P.lod.y, uintBitsToFloat(state));
    paths[4u * path + 3u] = vec4(reflect(direction, n), uintBitsToFloat(pixel));
    uint k = atomicAdd(queue[5], 1u);
    atomicMax(queue[8], (k + gl_WorkGroupSize.x) / gl_WorkGroupSize.x);
    pending[k] = path;
  } else {
    pixels[pixel] = packPixel(color);
  }
  countRays(rays);
}

// Pass 4: the pending mirror rays; a miss adds the background and writes the pixel, a hit is
// queued for pass 2.
void traceMirrorRays() {
  uint index = gl_GlobalInvocationID.x;
  if (index >= queue[5]) return;
  uint path = pending[index];
  vec4 p1 = paths[4u * path + 1u];
  vec4 p2 = paths[4u * path + 2u];
  vec4 p3 = paths[4u * path + 3u];
  uint state = floatBitsToUint(p2.w);
  uint pixel = floatBitsToUint(p3.w);
  atomicAdd(feedback[kFeedbackSecondaryRays], 1u);
  Hit hit;
  if (!traceScene(p2.xyz, p3.xyz, 0.0f, 1e30f, float(state & 3u) - 1.0f, false, p1.w, false,
                 hit)) {
    pixels[pixel] = packPixel(paths[4u * path].xyz + p1.xyz * background(p3.xyz));
    return;
  }
  uint slot = atomicAdd(queue[0], 1u);
  atomicMax(queue[1], (slot + gl_WorkGroupSize.x) / gl_WorkGroupSize.x);
  hits[4u * slot] = vec4(hit.t, hit.from, hit.occlusion, uintBitsToFloat(pixel));
  hits[4u * slot + 1u] = vec4(hit.normal, uintBitsToFloat(path));
  hits[4u * slot + 2u] = vec4(hit.color, uintBitsToFloat(state >> 2u));
  hits[4u * slot + 3u] = hit.irradiance;
}

// Pass 5: the photons of all lights (P.caustics.y), an invocation each in strides of the whole
// dispatch, summed into the caustic map.
void tracePhotons() {
  uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  uint traced = 0u;
  for (uint i = gl_GlobalInvocationID.x; i < P.caustics.y; i += stride) {
    tracePhoton(i);
    traced += 1u;
  }
  if (traced != 0u) atomicAdd(feedback[kFeedbackPhotons], traced);
}

void main() {
  if (kPass == 5u) {
    tracePhotons();
    return;
  }
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
  if (kPass == 4u) {
    traceMirrorRays();
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
