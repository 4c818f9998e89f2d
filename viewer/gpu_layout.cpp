// The C++ side of shaders/shared.h must lay structs out as std140/std430 GLSL does: these
// assertions pin every size and offset (the shader side is checked against the compiled SPIR-V
// by tests/viewer/layout_test.cpp).
#include <cstddef>

#include "iso/format.h"
#include "shaders/shared.h"

namespace iso::gpu {

// The shader's grid is the format's finest level.
static_assert(kGridLevels == kMaxLevel && kGridSize == float(1u << kMaxLevel) &&
              kGridMax == (1u << kMaxLevel) - 1u);

static_assert(sizeof(vec4) == 16 && sizeof(uvec4) == 16);
static_assert(sizeof(Light) == 64);
static_assert(offsetof(Light, position) == 0 && offsetof(Light, color) == 16 &&
              offsetof(Light, u) == 32 && offsetof(Light, v) == 48);
static_assert(offsetof(FrameParams, eye) == 0);
static_assert(offsetof(FrameParams, right) == 16);
static_assert(offsetof(FrameParams, up) == 32);
static_assert(offsetof(FrameParams, forward) == 48);
static_assert(offsetof(FrameParams, image) == 64);
static_assert(offsetof(FrameParams, options) == 80);
static_assert(offsetof(FrameParams, pool) == 96);
static_assert(offsetof(FrameParams, lod) == 112);
static_assert(offsetof(FrameParams, ambient) == 128);
static_assert(offsetof(FrameParams, albedo) == 144);
static_assert(offsetof(FrameParams, material) == 160);
static_assert(offsetof(FrameParams, medium) == 176);
static_assert(offsetof(FrameParams, skyTop) == 192);
static_assert(offsetof(FrameParams, skyBottom) == 208);
static_assert(offsetof(FrameParams, worldUp) == 224);
static_assert(offsetof(FrameParams, backface) == 240);
static_assert(offsetof(FrameParams, surface) == 256);
static_assert(offsetof(FrameParams, lights) == 272);
static_assert(offsetof(FrameParams, poolAddress) == 272 + kMaxLights * 64);
static_assert(offsetof(FrameParams, srgbToLinear) == 272 + kMaxLights * 64 + kPoolBuffers * 8);
static_assert(offsetof(FrameParams, srgbBounds) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 1024);
static_assert(offsetof(FrameParams, contentLo) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2048);
static_assert(offsetof(FrameParams, splatIndex) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2080);
static_assert(offsetof(FrameParams, splat) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2096);
static_assert(offsetof(FrameParams, ground) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2112);
static_assert(offsetof(FrameParams, groundColor) ==
              272 + kMaxLights * 64 + kPoolBuffers * 8 + 2128);
static_assert(offsetof(FrameParams, caustics) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2144);
static_assert(offsetof(FrameParams, causticDisc) ==
              272 + kMaxLights * 64 + kPoolBuffers * 8 + 2160);
static_assert(offsetof(FrameParams, causticU) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2176);
static_assert(offsetof(FrameParams, causticV) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2192);
static_assert(sizeof(FrameParams) == 272 + kMaxLights * 64 + kPoolBuffers * 8 + 2048 + 160);
static_assert(sizeof(ChunkEntry) == 16);
static_assert(kPageWords == 8192 && kWorkgroupSize == 64);

}  // namespace iso::gpu
