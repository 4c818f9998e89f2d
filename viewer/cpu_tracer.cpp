// The CPU reference tracer (cpu_tracer.h): shaders/trace.h inside a C++ class.
#include "cpu_tracer.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <glm/glm.hpp>
#include <glm/packing.hpp>

#include "iso/check.h"

namespace iso::viewer {
namespace shader {

using namespace glm;
using namespace iso::gpu;
#define ISO_INOUT(T) T&

// The GLSL environment of trace.h: the parameters and accessors that the shader gets from its
// bindings, here from host memory. Its member functions are the shader's functions.
class Tracer {
 public:
  Tracer(const CpuPool& pool, const FrameParams& params, const Environment* env)
      : P(params), pool_(pool), env_(env) {}

  FrameParams P;

  uint poolWord(uint word) { return pool_.words[word]; }
  uvec4 chunkState(uint chunk) { return pool_.chunks[chunk].state; }
  void requestChunk(uint) {}
  void useChunk(uint) {}
  vec3 environmentTexel(uint x, uint y) {
    const size_t at = 2 * (size_t(y) * env_->width + x);
    const vec2 rg = unpackHalf2x16(env_->texels[at]);
    const vec2 ba = unpackHalf2x16(env_->texels[at + 1]);
    return vec3(rg.x, rg.y, ba.x);
  }

#include "trace.h"

 private:
  const CpuPool& pool_;
  const Environment* env_;
};

#undef ISO_INOUT
}  // namespace shader

CpuPool buildCpuPool(const Asset& asset) {
  CpuPool pool;
  const auto chunks = asset.reader.chunks();
  pool.chunks.resize(chunks.size());
  std::vector<std::vector<uint32_t>> blobs(chunks.size());
  tbb::parallel_for(size_t(0), chunks.size(), [&](size_t i) {
    if (chunks[i].kind != kSurfaceKind) return;
    asset.reader.checkPayload(uint32_t(i));
    blobs[i] = buildBlob(decodeSurfaceChunk(asset.reader, uint32_t(i)), uint32_t(i), asset.tree,
                         asset.blob);
  });
  size_t pages = 0;
  for (const auto& b : blobs) pages += blobPages(b.size());
  pool.words.assign(pages * gpu::kPageWords, 0);
  uint32_t next = 0;
  for (size_t i = 0; i < chunks.size(); ++i) {
    gpu::ChunkEntry& e = pool.chunks[i];
    e.state = {gpu::kNotResident, chunks[i].level, glm::floatBitsToUint(chunks[i].geometricError),
               chunks[i].parent};
    if (blobs[i].empty()) continue;
    std::vector<uint32_t>& b = blobs[i];
    const uint32_t n = blobPages(b.size());
    for (uint32_t p = 0; p < n; ++p) b[gpu::kBlobPageList + p] = next + p;
    std::copy(b.begin(), b.end(), pool.words.begin() + size_t(next) * gpu::kPageWords);
    e.state.x = next;
    next += n;
  }
  return pool;
}

FrameSetup cpuFrameSetup(const Asset& asset, uint32_t width, uint32_t height,
                         const Environment* environment) {
  FrameSetup setup;
  setup.width = width;
  setup.height = height;
  setup.topChunk = asset.tree.topChunk();
  setup.chunkCount = uint32_t(asset.reader.chunks().size());
  setup.normals = asset.blob.normals;
  setup.colors = asset.blob.colors;
  setup.occlusion = asset.blob.occlusion;
  setup.requests = false;
  setup.environmentWidth = environment ? environment->width : 0;
  setup.environmentHeight = environment ? environment->height : 0;
  return setup;
}

CpuFrame renderCpu(const CpuPool& pool, const gpu::FrameParams& params,
                   const Environment* environment) {
  CpuFrame frame;
  const uint32_t width = params.image.x, height = params.image.y;
  frame.pixels.resize(size_t(width) * height);
  std::atomic<uint64_t> rays{0};
  tbb::parallel_for(uint32_t(0), height, [&](uint32_t y) {
    shader::Tracer tracer(pool, params, environment);
    uint32_t count = 0;
    for (uint32_t x = 0; x < width; ++x)
      frame.pixels[size_t(y) * width + x] = tracer.renderPixel(x, y, count);
    rays += count;
  });
  frame.rays = rays;
  return frame;
}

std::optional<CpuHit> traceCpu(const CpuPool& pool, const gpu::FrameParams& params,
                               glm::vec3 origin, glm::vec3 direction, bool inside) {
  shader::Tracer tracer(pool, params, nullptr);
  shader::Tracer::Hit hit;
  uint32_t rays = 0;
  if (!tracer.intersect(origin, direction, 0.0f, 1e30f, inside, 0.0f, false, hit, rays))
    return std::nullopt;
  return CpuHit{hit.t, hit.normal};
}

}  // namespace iso::viewer
