// Point set surfaces ray traced on the GPU (specs/viewer.md, "Point set surfaces"): an
// invocation a pixel traces its camera ray through shaders/pss_trace.h, which viewer/pss.cpp
// runs on the CPU from the same source; viewer/pss_gpu.cpp records the one dispatch.
#version 450
#extension GL_GOOGLE_include_directive : require

#define ISO_INOUT(T) inout T
#include "shared.h"

layout(local_size_x = 64) in;

layout(std140, binding = 0) uniform Pass { PssParams Q; };
layout(std430, binding = 1) readonly buffer Positions { vec4 positions[]; };  // xyz, h
layout(std430, binding = 2) readonly buffer Normals { vec4 normals[]; };
layout(std430, binding = 3) readonly buffer Colors { vec4 colors[]; };
layout(std430, binding = 4) readonly buffer Patches { vec4 patches[]; };  // 4 a point
// The grid (PssSurface::Grid): each cell's points and the trust regions reaching into it.
layout(std430, binding = 5) readonly buffer PointStart { uint pointStart[]; };
layout(std430, binding = 6) readonly buffer Points { uint points[]; };
layout(std430, binding = 7) readonly buffer ReachStart { uint reachStart[]; };
layout(std430, binding = 8) readonly buffer Reach { uint reach[]; };
// The picture: sRGB8 RGBA words.
layout(std430, binding = 9) writeonly buffer Pixels { uint pixels[]; };
// The volume (PssVolume): its grid's cells' points and the points (position, value).
layout(std430, binding = 10) readonly buffer VolumeStart { uint volumeStart[]; };
layout(std430, binding = 11) readonly buffer VolumeOrder { uint volumeOrder[]; };
layout(std430, binding = 12) readonly buffer VolumePoints { vec4 volumePoints[]; };

vec3 pssGridLo() { return vec3(Q.gridLo); }
float pssGridSide() { return Q.gridLo.w; }
ivec3 pssGridDims() { return ivec3(Q.gridDims.xyz); }
uint pssPointStart(uint c) { return pointStart[c]; }
uint pssPointAt(uint k) { return points[k]; }
uint pssReachStart(uint c) { return reachStart[c]; }
uint pssReachAt(uint k) { return reach[k]; }
vec3 pssPosition(uint i) { return vec3(positions[i]); }
vec3 pssNormal(uint i) { return vec3(normals[i]); }
float pssH(uint i) { return positions[i].w; }
vec4 pssPatch(uint i, int part) { return patches[4u * i + uint(part)]; }
vec4 pssSettings() { return Q.settings; }
uint pssLightCount() { return Q.gridDims.w; }
vec4 pssLight(uint l) { return Q.lights[l]; }
vec4 pssMaterial() { return Q.material; }
float pssReflectivity() { return Q.color.w; }
vec4 pssIors() { return Q.iors; }
vec3 pssColor(uint point) {
  return (Q.image.z & kPssColors) != 0u ? vec3(colors[point]) : vec3(Q.color);
}
vec3 pssBackground() { return vec3(Q.background); }
bool pssExact() { return (Q.image.z & kPssExact) != 0u; }
bool pssShadows() { return (Q.image.z & kPssShadows) != 0u; }
bool pssVolume() { return Q.volumeDims.w != 0u; }
vec4 pssVolumeSettings() { return Q.volumeSettings; }
vec3 pssVolumeLo() { return vec3(Q.volumeLo); }
float pssVolumeSide() { return Q.volumeLo.w; }
ivec3 pssVolumeDims() { return ivec3(Q.volumeDims.xyz); }
uint pssVolumeStart(uint c) { return volumeStart[c]; }
uint pssVolumeAt(uint k) { return volumeOrder[k]; }
vec4 pssVolumePoint(uint i) { return volumePoints[i]; }
uint pssTransferCount() { return Q.volumeDims.w; }
vec4 pssTransfer(uint k) { return Q.transfer[2u * k]; }
vec4 pssTransferColor(uint k) { return Q.transfer[2u * k + 1u]; }

#include "pss.h"
#include "pss_trace.h"

#include "pixel.h"

void main() {
  uint id = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
  if (id >= Q.image.x * Q.image.y) return;
  uint x = id % Q.image.x, y = id / Q.image.x;
  // Through the pixel's centre, as renderPss.
  float sx = (float(x) + 0.5f) / float(Q.image.x) * 2.0f - 1.0f;
  float sy = 1.0f - (float(y) + 0.5f) / float(Q.image.y) * 2.0f;
  vec3 d = normalize(vec3(Q.forward) + sx * vec3(Q.right) + sy * vec3(Q.up));
  pixels[id] = pixelWord(pssRayColor(vec3(Q.eye), d, Q.eye.w));
}
