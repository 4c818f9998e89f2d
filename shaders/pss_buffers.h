// A point set surface and the volume inside it on the GPU: the storage buffers (bindings
// ISO_PSS_BINDING to ISO_PSS_BINDING + kPssStorageBindings - 1, in the order of
// viewer/pss_gpu.h's PssBuffers) and the accessors pss.h, pss_volume.h and pss_trace.h read them
// by. The includer declares `PssParams Q` (a uniform or a storage buffer) and defines
// ISO_PSS_BINDING first. GLSL only: the C++ builds read host arrays (tracer/pss.cpp,
// tracer/cpu_tracer.cpp).
layout(std430, binding = ISO_PSS_BINDING) readonly buffer PssPositions { vec4 pssPositions[]; };  // xyz, h
layout(std430, binding = ISO_PSS_BINDING + 1) readonly buffer PssNormals { vec4 pssNormals[]; };
layout(std430, binding = ISO_PSS_BINDING + 2) readonly buffer PssColors { vec4 pssColors[]; };
layout(std430, binding = ISO_PSS_BINDING + 3) readonly buffer PssPatches { vec4 pssPatches[]; };  // 4 a point
// The grid (PssSurface::Grid): each cell's points and the trust regions reaching into it.
layout(std430, binding = ISO_PSS_BINDING + 4) readonly buffer PssPointStart { uint pssPointStarts[]; };
layout(std430, binding = ISO_PSS_BINDING + 5) readonly buffer PssPoints { uint pssPoints[]; };
layout(std430, binding = ISO_PSS_BINDING + 6) readonly buffer PssReachStart { uint pssReachStarts[]; };
layout(std430, binding = ISO_PSS_BINDING + 7) readonly buffer PssReach { uint pssReaches[]; };
// The volume (PssVolume): its grid's cells' points and the points (position, value).
layout(std430, binding = ISO_PSS_BINDING + 8) readonly buffer PssVolumeStart { uint pssVolumeStarts[]; };
layout(std430, binding = ISO_PSS_BINDING + 9) readonly buffer PssVolumeOrder { uint pssVolumeOrder[]; };
layout(std430, binding = ISO_PSS_BINDING + 10) readonly buffer PssVolumePoints { vec4 pssVolumePoints[]; };

vec3 pssGridLo() { return vec3(Q.gridLo); }
float pssGridSide() { return Q.gridLo.w; }
ivec3 pssGridDims() { return ivec3(Q.gridDims.xyz); }
uint pssPointStart(uint c) { return pssPointStarts[c]; }
uint pssPointAt(uint k) { return pssPoints[k]; }
uint pssReachStart(uint c) { return pssReachStarts[c]; }
uint pssReachAt(uint k) { return pssReaches[k]; }
vec3 pssPosition(uint i) { return vec3(pssPositions[i]); }
vec3 pssNormal(uint i) { return vec3(pssNormals[i]); }
float pssH(uint i) { return pssPositions[i].w; }
vec4 pssPatch(uint i, int part) { return pssPatches[4u * i + uint(part)]; }
vec4 pssSettings() { return Q.settings; }
uint pssLightCount() { return Q.gridDims.w; }
vec4 pssLight(uint l) { return Q.lights[l]; }
vec4 pssMaterial() { return Q.material; }
float pssReflectivity() { return Q.color.w; }
vec4 pssIors() { return Q.iors; }
vec3 pssColor(uint point) {
  return (Q.image.z & kPssColors) != 0u ? vec3(pssColors[point]) : vec3(Q.color);
}
vec3 pssBackground() { return vec3(Q.background); }
bool pssExact() { return (Q.image.z & kPssExact) != 0u; }
float pssSkip() { return Q.eye.w; }  // the viewer's tracer: how far rays leaving a surface skip it
bool pssShadows() { return (Q.image.z & kPssShadows) != 0u; }
bool pssVolume() { return Q.volumeDims.w != 0u; }
vec4 pssVolumeSettings() { return Q.volumeSettings; }
vec3 pssVolumeLo() { return vec3(Q.volumeLo); }
float pssVolumeSide() { return Q.volumeLo.w; }
ivec3 pssVolumeDims() { return ivec3(Q.volumeDims.xyz); }
uint pssVolumeStart(uint c) { return pssVolumeStarts[c]; }
uint pssVolumeAt(uint k) { return pssVolumeOrder[k]; }
vec4 pssVolumePoint(uint i) { return pssVolumePoints[i]; }
uint pssTransferCount() { return Q.volumeDims.w; }
vec4 pssTransfer(uint k) { return Q.transfer[2u * k]; }
vec4 pssTransferColor(uint k) { return Q.transfer[2u * k + 1u]; }
