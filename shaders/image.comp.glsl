// Image-space point rendering on the GPU (specs/viewer.md, "Image-space points"): the steps of
// shaders/image.h, one stage a pipeline (specialization constant 0), over every point or pixel.
// viewer/point_image_gpu.cpp records them in order; tracer/point_image.cpp runs the same steps
// on the CPU.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

#define ISO_INOUT(T) inout T
#include "shared.h"

// The stages (kImageStage...: shared.h).
layout(constant_id = 0) const uint kStage = 0u;
// The fill and control stages' kind: 0 background pixels, 1 occluded pixels; for control also 2,
// the start of filling, and 3, the start of shading.
layout(constant_id = 1) const uint kKind = 0u;

layout(local_size_x = 64) in;

layout(std140, binding = 0) uniform Pass { ImageParams Q; };
layout(std430, binding = 1) readonly buffer Positions { vec4 positions[]; };  // xyz, spacing
layout(std430, binding = 2) readonly buffer Normals { vec4 normals[]; };
layout(std430, binding = 3) readonly buffer Colors { vec4 colors[]; };
// Layers: per pixel (point, depth bits), the two words of a 64-bit key (depth bits << 32 |
// point); background: no point, and depth bits 0 or all ones. A the layer, B the fill stage's
// output (the host swaps the two buffers' bindings after each filling pass), R the previous
// layer (depth peeling). Keys is layer A's buffer seen as keys: projection leaves there, per
// pixel, the least key of the points projected into it (the host fills it with all ones).
layout(std430, binding = 4) buffer Keys { uint64_t keys[]; };
layout(std430, binding = 5) buffer LayerA { uvec2 layerA[]; };
layout(std430, binding = 6) buffer LayerB { uvec2 layerB[]; };
layout(std430, binding = 7) buffer LayerR { uvec2 layerR[]; };
// Shaded colors (premultiplied RGBA), which smoothing reads (binding 9 is unused).
layout(std430, binding = 8) buffer ColorA { vec4 colorA[]; };
// The layers blended so far, front to back (premultiplied RGBA).
layout(std430, binding = 10) buffer Blend { vec4 blended[]; };
// Per point and light, the samples of the light that reach it (shadow textures).
layout(std430, binding = 11) buffer Lit { uint lit[]; };
// Words: 0-2 the fill stage's indirect dispatch, 3 pixels the last fill pass changed, 4 fill
// passes that changed something (kImageControl...: shared.h).
layout(std430, binding = 12) buffer Control { uint control[]; };
// The picture: sRGB8 RGBA words; the background in the scene's color.
layout(std430, binding = 13) writeonly buffer Pixels { uint pixels[]; };
// Filling's tiles (kImageFillTile pixels square), T of the image: two arrays of marks (a word a
// tile), four lists of tiles (T words each, from word 2T; a tile listed as its x | y << 16), and
// the shading's marks (from word 6T). Round r runs over list r % 2 and wakes the tiles near a
// pixel it changed for round r + 1: the first to set a tile's mark in array
// (r + 1) % 2 to r + 1 appends it to list (r + 1) % 2. A tile left out did not change in the
// round before, nor did any pixel within the masks' reach: both layer buffers already hold its
// values. Round 0 runs over list 2, the tiles that projection left a point in or next to (mark
// 0 in array 0; array 1 marks 0 the tiles with a point): no pixel elsewhere is a candidate of
// either kind, before or after filling the background (a filled pixel lies next to a covered
// one). Every tile listed is also listed once in list 3 (the shading's marks), which the
// shading stages run over: every covered pixel's tile and the tiles around it, beyond which
// shading, smoothing and anti-aliasing give nothing to blend.
layout(std430, binding = 14) buffer Tiles { uint tiles[]; };

bool inside(ivec2 p) { return p.x >= 0 && p.y >= 0 && p.x < int(Q.image.x) && p.y < int(Q.image.y); }
uint at(ivec2 p) { return uint(p.y) * Q.image.x + uint(p.x); }

vec3 pointPosition(uint i) { return vec3(positions[i]); }
vec3 pointNormal(uint i) { return vec3(normals[i]); }
vec4 pointColor(uint i) { return colors[i]; }
float pointSpacing(uint i) { return positions[i].w; }
float pointShadow(uint i, uint light) {
  return float(lit[i * uint(Q.ambient.w) + light]) / Q.lights[light].color.w;
}
// A layer's depth word as a depth (0: background).
float depthOf(uint bits) { return bits == 0xFFFFFFFFu ? 0.0f : uintBitsToFloat(bits); }
// The smoothing stage (smoothTile) reads a tile's neighbourhood once into windows: the depths
// and shaded colors of the tile and two pixels around (windowDepth, windowColor), then the
// smoothed colors of the tile and a pixel around (windowSmooth), which anti-aliasing reads.
const int kWindow = int(kImageFillTile) + 4, kSmoothed = int(kImageFillTile) + 2;
float windowDepth[kWindow * kWindow];
vec4 windowColor[kWindow * kWindow];
vec4 windowSmooth[kSmoothed * kSmoothed];
ivec2 windowOrigin = ivec2(0);  // the tile's first pixel
bool windowSmoothed = false;    // layerColor reads the smoothed colors
float layerDepth(ivec2 p) {
  if (kStage == kImageStageSmooth) {
    ivec2 q = p - windowOrigin + 2;
    return windowDepth[q.y * kWindow + q.x];
  }
  return inside(p) ? depthOf(layerA[at(p)].y) : 0.0f;
}
uint layerIndex(ivec2 p) { return inside(p) ? layerA[at(p)].x : kImageNoPoint; }
float referenceDepth(ivec2 p) { return inside(p) ? depthOf(layerR[at(p)].y) : 0.0f; }
vec4 layerColor(ivec2 p) {
  if (windowSmoothed) {
    ivec2 q = p - windowOrigin + 1;
    return windowSmooth[q.y * kSmoothed + q.x];
  }
  ivec2 q = p - windowOrigin + 2;
  return windowColor[q.y * kWindow + q.x];
}

#include "image.h"

// Wake pixel p's tile and the eight around it: mark them `mark` in array mark % 2 and list them
// in list `list`, once each.
void wakeTiles(ivec2 p, uint mark, uint list) {
  uint tilesX = (Q.image.x + kImageFillTile - 1u) / kImageFillTile;
  uint tilesY = (Q.image.y + kImageFillTile - 1u) / kImageFillTile;
  uint tileCount = tilesX * tilesY;
  ivec2 tile = p / int(kImageFillTile);
  for (int ty = max(tile.y - 1, 0); ty <= min(tile.y + 1, int(tilesY) - 1); ++ty)
    for (int tx = max(tile.x - 1, 0); tx <= min(tile.x + 1, int(tilesX) - 1); ++tx) {
      uint u = uint(ty) * tilesX + uint(tx);
      if (atomicExchange(tiles[(mark & 1u) * tileCount + u], mark) != mark) {
        uint xy = uint(tx) | uint(ty) << 16;  // listed as coordinates: no division to undo
        tiles[(2u + list) * tileCount + atomicAdd(control[kImageControlTiles + list], 1u)] = xy;
        if (atomicExchange(tiles[6u * tileCount + u], 0u) != 0u)
          tiles[5u * tileCount + atomicAdd(control[kImageControlTiles + 3u], 1u)] = xy;
      }
    }
}

// The tile of this invocation (64 a workgroup) from `list` (kImageControlTiles + list counts
// them): its first pixel, or false past the list.
bool invocationTile(uint list, out ivec2 origin) {
  uint tilesX = (Q.image.x + kImageFillTile - 1u) / kImageFillTile;
  uint tileCount = tilesX * ((Q.image.y + kImageFillTile - 1u) / kImageFillTile);
  uint listed = (gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x) * 64u +
                gl_LocalInvocationID.x;
  origin = ivec2(0);
  if (listed >= control[kImageControlTiles + list]) return false;
  uint t = tiles[(2u + list) * tileCount + listed];
  origin = ivec2(int(t & 0xFFFFu), int(t >> 16)) * int(kImageFillTile);
  return true;
}

// A filling round: an invocation a tile. Its pixels and those a pixel around are read once
// (lavapipe pays for every load, lane by lane), and each pixel's 3×3 neighbours are taken from
// them, as imageFill takes them; the masks' rings beyond, for the few pixels that get that far,
// are read from the layer (imageFillBeyond). Reading the 3×3 through layerDepth from the window
// measured a third slower.
void fillTile() {
  uint pass = control[kImageControlRound];
  ivec2 origin;
  if (!invocationTile(pass == 0u ? 2u : (pass & 1u), origin)) return;
  const int kWide = int(kImageFillTile) + 2;
  float depths[kWide * kWide];
  uint points[kWide * kWide];
  for (int k = 0; k < kWide * kWide; ++k) {
    ivec2 q = origin - 1 + ivec2(k % kWide, k / kWide);
    uvec2 v = inside(q) ? layerA[at(q)] : uvec2(kImageNoPoint, 0u);
    depths[k] = depthOf(v.y);
    points[k] = v.x;
  }
  uint changed = 0u;
  for (int k = 0; k < int(kImageFillTile * kImageFillTile); ++k) {
    ivec2 p = origin + ivec2(k % int(kImageFillTile), k / int(kImageFillTile));
    if (!inside(p)) continue;
    int centre = (k / int(kImageFillTile) + 1) * kWide + k % int(kImageFillTile) + 1;
    float self = depths[centre];
    float depth = self;
    uint index = points[centre];
    if ((kKind == 0u) == (self == 0.0f)) {
      // imageFill's 3×3 part, in its order
      float best = 2.0f;
      uint from = kImageNoPoint;
      uint ring = 0u;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          float d = depths[centre + dy * kWide + dx];
          if ((dx == 0 && dy == 0) || !imageCovers(d, self)) continue;
          ring |= imageMaskBits(dx, dy);
          if (d < best) {
            best = d;
            from = points[centre + dy * kWide + dx];
          }
        }
      if (best <= 1.0f && imageFillBeyond(p, int(pass), self, best, from, ring, depth, index))
        ++changed;
    }
    layerB[at(p)] = uvec2(index, floatBitsToUint(depth));
  }
  // The tiles a changed pixel wakes are its tile's and those around: once for the tile.
  if (changed != 0u) {
    atomicAdd(control[kImageControlChanged], changed);
    wakeTiles(origin, pass + 1u, (pass + 1u) & 1u);
  }
}

#include "pixel.h"

// Shading: an invocation a tile of list 3, pixel after pixel.
void shadeTile() {
  ivec2 origin;
  if (!invocationTile(3u, origin)) return;
  for (int k = 0; k < int(kImageFillTile * kImageFillTile); ++k) {
    ivec2 p = origin + ivec2(k % int(kImageFillTile), k / int(kImageFillTile));
    if (inside(p)) colorA[at(p)] = imageShade(p);
  }
}

// Smoothing, anti-aliasing and blending: an invocation a tile of list 3. Its neighbourhood is
// read once into the windows (lavapipe pays for every load, lane by lane), smoothed, then each
// pixel anti-aliased and blended under the layers before (layer A kept as R), and the picture's
// pixel written over the background (the host filled the picture with the background).
void smoothTile() {
  ivec2 origin;
  if (!invocationTile(3u, origin)) return;
  windowOrigin = origin;
  for (int k = 0; k < kWindow * kWindow; ++k) {
    ivec2 q = origin - 2 + ivec2(k % kWindow, k / kWindow);
    float depth = inside(q) ? depthOf(layerA[at(q)].y) : 0.0f;
    windowDepth[k] = depth;
    windowColor[k] = depth > 0.0f ? colorA[at(q)] : vec4(0.0f);  // background: transparent
  }
  for (int k = 0; k < kSmoothed * kSmoothed; ++k)
    windowSmooth[k] = imageSmooth(origin - 1 + ivec2(k % kSmoothed, k / kSmoothed));
  windowSmoothed = true;
  for (int k = 0; k < int(kImageFillTile * kImageFillTile); ++k) {
    ivec2 p = origin + ivec2(k % int(kImageFillTile), k / int(kImageFillTile));
    if (!inside(p)) continue;
    uint id = at(p);
    vec4 c = imageAntialias(p);
    // The first layer blends over nothing; the only one keeps nothing for a next.
    vec4 sum = (Q.image.w & kImagePeel) == 0u ? c : blended[id] + (1.0f - blended[id].a) * c;
    if ((Q.image.w & kImageOnlyLayer) == 0u) {
      blended[id] = sum;
      layerR[id] = layerA[id];
    }
    pixels[id] = pixelWord(vec3(sum) + (1.0f - sum.a) * vec3(Q.background));
  }
}

void main() {
  if (kStage == kImageStageFill) {
    fillTile();
    return;
  }
  if (kStage == kImageStageShade) {
    shadeTile();
    return;
  }
  if (kStage == kImageStageSmooth) {
    smoothTile();
    return;
  }
  // Dispatches wider than a row of workgroups continue on the next rows (gl_NumWorkGroups.y).
  uint id = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
  if (kStage == kImageStageProject || kStage == kImageStageLit) {
    if (id >= uint(positions.length())) return;
    vec3 p = pointPosition(id);
    // Projection reads the normal only to cull (lavapipe pays for every load).
    bool normal = kStage == kImageStageLit || (Q.image.w & kImageCull) != 0u;
    vec3 n = normal ? pointNormal(id) : vec3(0.0f);
    if (kStage == kImageStageLit) {
      // The light's first layer, filled, is layer A; material.w names the pass's light.
      if (imageLit(p, n)) atomicAdd(lit[id * uint(Q.ambient.w) + uint(Q.material.w)], 1u);
      return;
    }
    ivec2 pixel = ivec2(0);
    float depth = 0.0f;
    if (!imageProject(p, n, pixel, depth) || !imageBehindLast(pixel, depth)) return;
    uint64_t key = (uint64_t(floatBitsToUint(depth)) << 32) | uint64_t(id);
    if (atomicMin(keys[at(pixel)], key) != ~0ul) return;
    // The first point of its pixel; the first of its tile (marked 0 in array 1) wakes the tile
    // and the tiles around for round 0 of filling.
    uint tilesX = (Q.image.x + kImageFillTile - 1u) / kImageFillTile;
    uint tileCount = tilesX * ((Q.image.y + kImageFillTile - 1u) / kImageFillTile);
    uint own = uint(pixel.y) / kImageFillTile * tilesX + uint(pixel.x) / kImageFillTile;
    if (tiles[tileCount + own] != 0u && atomicExchange(tiles[tileCount + own], 0u) != 0u)
      wakeTiles(pixel, 0u, 2u);
    return;
  }
  if (kStage == kImageStageControl) {
    // After a fill pass: the next runs over the tiles it woke (none once one changed nothing).
    // Kind 2 starts filling: round 0 over the tiles projection listed.
    if (id != 0u) return;
    if (kKind >= 2u) {  // 3: the shading stages' dispatch, over list 3
      // Filling and shading take 64 tiles a workgroup (an invocation a tile).
      uint first = control[kImageControlTiles + kKind];
      uint groups = (first + 63u) / 64u;
      uint x = min(groups, 65535u);
      control[0] = x;
      control[1] = x == 0u ? 1u : (groups + x - 1u) / x;
      control[2] = 1u;
      control[kImageControlChanged] = 0u;
      control[kImageControlRound] = 0u;
      control[kImageControlTiles] = 0u;
      control[kImageControlTiles + 1u] = 0u;
      return;
    }
    bool changed = control[kImageControlChanged] != 0u;
    if (changed) control[kImageControlPasses + kKind] += 1u;
    uint next = control[kImageControlRound] + 1u;
    uint listed = changed ? control[kImageControlTiles + (next & 1u)] : 0u;
    uint groups = (listed + 63u) / 64u;
    uint x = min(groups, 65535u);
    control[0] = x;
    control[1] = x == 0u ? 1u : (groups + x - 1u) / x;
    control[2] = 1u;
    control[kImageControlTiles + ((next + 1u) & 1u)] = 0u;  // the list round next + 1 gets
    control[kImageControlChanged] = 0u;
    control[kImageControlRound] = next;
    return;
  }
}
