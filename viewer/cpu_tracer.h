// The CPU reference tracer: the shaders' tracing code (shaders/trace.h) compiled as C++ and run
// over every pixel with TBB, on the whole file resident. Golden tests compare the GPU's pictures
// with its pictures; it is also `iso view --cpu`.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "asset.h"
#include "image.h"
#include "shared.h"

namespace iso::viewer {

// Every surface chunk of an asset as blobs in one host page pool, and the chunk table.
struct CpuPool {
  std::vector<uint32_t> words;
  std::vector<gpu::ChunkEntry> chunks;
};
CpuPool buildCpuPool(const Asset& asset);

struct CpuFrame {
  std::vector<uint32_t> pixels;  // RGBA8
  uint64_t rays = 0;
};

// The frame setup of the CPU tracer for an asset (everything resident, no requests).
FrameSetup cpuFrameSetup(const Asset& asset, uint32_t width, uint32_t height,
                         const Environment* environment);

// Render a frame. params.pool is ignored (the host pool is one array).
CpuFrame renderCpu(const CpuPool& pool, const gpu::FrameParams& params,
                   const Environment* environment);

// The first surface hit of one ray (frame units) with the tracer's rules, for tests.
struct CpuHit {
  float t = 0;
  glm::vec3 normal{};
};
std::optional<CpuHit> traceCpu(const CpuPool& pool, const gpu::FrameParams& params,
                               glm::vec3 origin, glm::vec3 direction, bool inside = false);

}  // namespace iso::viewer
