// Point set surfaces ray traced on the GPU (specs/viewer.md, "Point set surfaces"): an
// invocation a pixel traces its camera ray through shaders/pss_trace.h, which tracer/pss.cpp
// runs on the CPU from the same source; viewer/pss_gpu.cpp records the one dispatch.
#version 450
#extension GL_GOOGLE_include_directive : require

#define ISO_INOUT(T) inout T
#include "shared.h"

layout(local_size_x = 64) in;

layout(std140, binding = 0) uniform Pass { PssParams Q; };
// The surface and its volume: bindings 1 to kPssStorageBindings (pss_buffers.h).
#define ISO_PSS_BINDING 1
#include "pss_buffers.h"
// The picture: sRGB8 RGBA words.
layout(std430, binding = 12) writeonly buffer Pixels { uint pixels[]; };

#include "pss.h"
#include "pss_volume.h"
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
