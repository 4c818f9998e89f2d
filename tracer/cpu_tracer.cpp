// The CPU reference tracer (cpu_tracer.h): shaders/trace.h inside a C++ class.
#include "tracer/cpu_tracer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <glm/glm.hpp>
#include <glm/packing.hpp>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/points.h"
#include "tracer/splats.h"

namespace iso::viewer {
namespace shader {

using namespace glm;
using namespace iso::gpu;
#define ISO_INOUT(T) T&
#define ISO_PRECISE
#define ISO_ADDRESS uint64_t

// The GLSL environment of trace.h: the parameters and accessors that the shader gets from its
// bindings, here from host memory. Its member functions are the shader's functions.
class Tracer {
 public:
  // `caustics`: the caustic map (read by shading, or summed into by photons: `photons`).
  Tracer(const CpuPool& pool, const FrameParams& params, const Environment* env,
         uint32_t* caustics = nullptr, bool photons = false)
      : P(params),
        Q(pool.pss ? pool.pss->params(params) : PssParams{}),
        pool_(pool),
        env_(env),
        caustics_(caustics),
        photons_(photons) {}

  FrameParams P;
  PssParams Q;  // the point set surface's (pss_buffers.h), when the pool has one

  uint64_t blobBase(uint firstPage) { return uint64_t(firstPage) * kPageWords; }
  uint blobWord(uint64_t base, uint word) { return pool_.words[base + word]; }
  uvec2 blobPair(uint64_t base, uint word) {
    return uvec2(pool_.words[base + word], pool_.words[base + word + 1]);
  }
  uvec4 chunkState(uint chunk) { return pool_.chunks[chunk].state; }
  void requestChunk(uint) {}
  void useChunk(uint) {}
  bool floatDistances() const { return (P.options.x & kOptionFloatDistances) != 0u; }
  bool flatTraversal() const { return (P.options.x & kOptionFlatTraversal) != 0u; }
  static bool splatsCompiled() { return true; }
  // The point set surface (pss.h, pss_volume.h), as shaders/pss_buffers.h reads it on the GPU.
  bool pssCompiled() const { return pool_.pss != nullptr; }
  const PssSurface& pssSurface() const { return *pool_.pss->surface; }
  vec3 pssGridLo() const { return vec3(Q.gridLo); }
  float pssGridSide() const { return Q.gridLo.w; }
  ivec3 pssGridDims() const { return ivec3(Q.gridDims); }
  uint pssPointStart(uint c) const { return pssSurface().grid().pointStart[c]; }
  uint pssPointAt(uint k) const { return pssSurface().grid().points[k]; }
  uint pssReachStart(uint c) const { return pssSurface().grid().reachStart[c]; }
  uint pssReachAt(uint k) const { return pssSurface().grid().reach[k]; }
  vec3 pssPosition(uint i) const { return pssSurface().positions()[i]; }
  vec3 pssNormal(uint i) const { return pssSurface().normals()[i]; }
  float pssH(uint i) const { return pssSurface().h()[i]; }
  vec4 pssPatch(uint i, int part) const {
    const PssPatch& p = pssSurface().patches()[i];
    return part == 0 ? p.origin : part == 1 ? p.normal : part == 2 ? p.tangent : p.coefficients;
  }
  vec4 pssSettings() const { return Q.settings; }
  vec3 pssColor(uint point) const {
    return (Q.image.z & kPssColors) != 0u ? pool_.pss->colors[point] : vec3(Q.color);
  }
  bool pssExact() const { return (Q.image.z & kPssExact) != 0u; }
  float pssSkip() const { return Q.eye.w; }
  bool pssVolume() const { return Q.volumeDims.w != 0u; }
  vec4 pssVolumeSettings() const { return Q.volumeSettings; }
  vec3 pssVolumeLo() const { return vec3(Q.volumeLo); }
  float pssVolumeSide() const { return Q.volumeLo.w; }
  ivec3 pssVolumeDims() const { return ivec3(Q.volumeDims); }
  uint pssVolumeStart(uint c) const { return pool_.pss->volume->start()[c]; }
  uint pssVolumeAt(uint k) const { return pool_.pss->volume->order()[k]; }
  vec4 pssVolumePoint(uint i) const { return pool_.pss->volume->points()[i]; }
  uint pssTransferCount() const { return Q.volumeDims.w; }
  vec4 pssTransfer(uint k) const { return Q.transfer[2u * k]; }
  vec4 pssTransferColor(uint k) const { return Q.transfer[2u * k + 1u]; }
  float lodPixels() const { return photons_ ? -1.0f : P.lod.x; }
  uint causticWord(uint word) const { return caustics_ ? caustics_[word] : 0u; }
  void depositCaustic(uint word, uint value) {
    std::atomic_ref<uint32_t>(caustics_[word]).fetch_add(value, std::memory_order_relaxed);
  }
  static vec3 fusedMultiplyAdd(vec3 a, vec3 b, vec3 c) {
    return vec3(std::fma(a.x, b.x, c.x), std::fma(a.y, b.y, c.y), std::fma(a.z, b.z, c.z));
  }
  vec3 environmentTexel(uint x, uint y) {
    const size_t at = 2 * (size_t(y) * env_->width + x);
    const vec2 rg = unpackHalf2x16(env_->texels[at]);
    const vec2 ba = unpackHalf2x16(env_->texels[at + 1]);
    return vec3(rg.x, rg.y, ba.x);
  }

#include "shaders/trace.h"

 private:
  const CpuPool& pool_;
  const Environment* env_;
  uint32_t* caustics_;  // the caustic map (shared.h, kCausticCells), or none
  bool photons_;        // tracing caustic photons (at the finest level resident)
};

#undef ISO_INOUT
#undef ISO_PRECISE
#undef ISO_ADDRESS
}  // namespace shader

CpuPool buildCpuPool(const Reader& reader, const ChunkFilter& holds, bool splats) {
  CpuPool pool;
  const auto chunks = reader.chunks();
  const ChunkTree tree(chunks);
  if (tree.topChunk() == kNoParent)
    throw FileError(reader.name(), std::nullopt, "the file holds no surface to trace");
  pool.topChunk = tree.topChunk();
  pool.blob = blobOptionsOf(reader);
  std::optional<SplatIndex> index;
  if (splats) index = buildSplatIndex(reader);
  const size_t count = chunks.size() + (index ? 1 : 0);
  pool.chunks.resize(count);
  std::vector<std::vector<uint32_t>> blobs(count);
  tbb::parallel_for(size_t(0), chunks.size(), [&](size_t i) {
    if (holds && !holds(chunks[i])) return;
    if (chunks[i].kind == kSurfaceKind)
      blobs[i] = buildBlob(decodeBlobChunk(reader, uint32_t(i), pool.blob), uint32_t(i), tree, pool.blob);
    else if (chunks[i].kind == kPointsKind && index)
      blobs[i] = buildSplatBlob(decodePointsChunk(reader, uint32_t(i)), chunks[i]);
  });
  for (size_t i = 0; i < chunks.size(); ++i)
    if (chunks[i].kind == kPointsKind && !blobs[i].empty()) {
      pool.splatPoints += blobs[i][gpu::kSplatCount];
      pool.splatBytes += blobs[i].size() * 4;
    }
  if (index) {
    pool.splatIndex = index->chunk;
    pool.splatRadius = index->typicalRadius;
    blobs[index->chunk] = std::move(index->words);
  }
  const auto pagesOf = [](size_t words) { return (words + gpu::kPageWords - 1) / gpu::kPageWords; };
  size_t pages = 0;
  for (const auto& b : blobs) pages += pagesOf(b.size());
  pool.words.assign(pages * gpu::kPageWords, 0);
  uint32_t next = 0;
  for (size_t i = 0; i < count; ++i) {
    gpu::ChunkEntry& e = pool.chunks[i];
    e.state = {gpu::kNotResident, 0u, 0u, gpu::kNotResident};
    if (i < chunks.size())
      e.state = {gpu::kNotResident, chunks[i].level,
                 glm::floatBitsToUint(chunks[i].geometricError), chunks[i].parent};
    if (blobs[i].empty()) continue;
    std::vector<uint32_t>& b = blobs[i];
    const uint32_t n = uint32_t(pagesOf(b.size()));
    std::copy(b.begin(), b.end(), pool.words.begin() + size_t(next) * gpu::kPageWords);
    e.state.x = next;
    next += n;
    std::vector<uint32_t>().swap(b);
  }
  return pool;
}

CausticMap causticMapCpu(const CpuPool& pool, const gpu::FrameParams& params) {
  CausticMap map;
  map.words.assign(size_t(3) * gpu::kCausticCells * gpu::kCausticCells, 0u);
  if (params.caustics.x == 0) return map;
  const auto t0 = std::chrono::steady_clock::now();
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, params.caustics.y, 4096),
                    [&](const tbb::blocked_range<uint32_t>& range) {
                      shader::Tracer tracer(pool, params, nullptr, map.words.data(), true);
                      for (uint32_t i = range.begin(); i < range.end(); ++i) tracer.tracePhoton(i);
                    });
  map.photons = params.caustics.y;
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return map;
}

CpuFrame renderCpu(const CpuPool& pool, const gpu::FrameParams& params,
                   const Environment* environment) {
  CpuFrame frame;
  CausticMap caustics;
  if (params.caustics.x > 0) caustics = causticMapCpu(pool, params);
  frame.photons = caustics.photons;
  frame.photonSeconds = caustics.seconds;
  const uint32_t width = params.image.x, height = params.image.y;
  frame.pixels.resize(size_t(width) * height);
  std::atomic<uint64_t> primary{0}, shadow{0}, secondary{0};
  // Tiles of 8×8 pixels, as the GPU's workgroups of kWorkgroupSize draw them.
  constexpr uint32_t kTile = 8;
  static_assert(kTile * kTile == gpu::kWorkgroupSize);
  const uint32_t tilesX = (width + kTile - 1) / kTile, tilesY = (height + kTile - 1) / kTile;
  tbb::parallel_for(uint32_t(0), tilesX * tilesY, [&](uint32_t tile) {
    shader::Tracer tracer(pool, params, environment,
                          caustics.photons > 0 ? caustics.words.data() : nullptr);
    const uint32_t x0 = tile % tilesX * kTile, y0 = tile / tilesX * kTile;
    const uint32_t x1 = std::min(x0 + kTile, width), y1 = std::min(y0 + kTile, height);
    const float start = tracer.tileStart(x0, y0, x1, y1);
    glm::uvec3 count(0u);
    for (uint32_t y = y0; y < y1; ++y)
      for (uint32_t x = x0; x < x1; ++x)
        frame.pixels[size_t(y) * width + x] = tracer.renderPixel(x, y, start, count);
    primary += count.x;
    shadow += count.y;
    secondary += count.z;
  });
  frame.rays = {primary, shadow, secondary};
  return frame;
}

float tileStartCpu(const CpuPool& pool, const gpu::FrameParams& params, uint32_t x0, uint32_t y0,
                   uint32_t x1, uint32_t y1) {
  ISO_CHECK(x0 < x1 && y0 < y1);
  return shader::Tracer(pool, params, nullptr).tileStart(x0, y0, x1, y1);
}

gpu::FrameParams finestFrameParams(const CpuPool& pool) {
  gpu::FrameParams p{};
  // The record layout follows what the records carry.
  p.options = {recordOptionBits(pool.blob), 0u, pool.topChunk, uint32_t(pool.chunks.size())};
  p.surface = glm::vec4(pool.blob.distanceUnit, 0.0f, 0.0f, 0.0f);
  p.lod = glm::vec4(-1.0f, 0.0f, 0.0f, 0.0f);  // no chunk's error is below a negative bound
  p.eye.w = 1.0f;
  p.contentLo = glm::vec4(0.0f);  // the root cube
  p.contentHi = glm::vec4(1.0f);
  setColorTable(p);
  return p;
}

gpu::FrameParams splatFrameParams(const CpuPool& pool, bool surfaceToo) {
  ISO_CHECK(pool.splatIndex != kNoParent);
  gpu::FrameParams p = finestFrameParams(pool);
  p.options.x |= gpu::kOptionSplats | (surfaceToo ? 0u : gpu::kOptionNoSurface);
  p.options.w = uint32_t(pool.chunks.size());
  p.splatIndex.x = pool.splatIndex;
  p.splat.x = kSplatBlendWindow;
  return p;
}

std::optional<CpuHit> traceCpu(const CpuPool& pool, const gpu::FrameParams& params,
                               glm::vec3 origin, glm::vec3 direction, float side, bool strict) {
  shader::Tracer tracer(pool, params, nullptr);
  shader::Tracer::Hit hit;
  if (!tracer.traceScene(origin, direction, 0.0f, 1e30f, side, strict, 0.0f, false, hit))
    return std::nullopt;
  return CpuHit{hit.t, hit.from, hit.normal};
}

void traceCpu(const CpuPool& pool, const gpu::FrameParams& params, std::span<const CpuRay> rays,
              std::span<std::optional<CpuHit>> hits) {
  ISO_CHECK(rays.size() == hits.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), 1024),
                    [&](const tbb::blocked_range<size_t>& range) {
                      shader::Tracer tracer(pool, params, nullptr);
                      for (size_t i = range.begin(); i < range.end(); ++i) {
                        shader::Tracer::Hit hit;
                        if (tracer.traceScene(rays[i].origin, rays[i].direction, rays[i].tMin,
                                             rays[i].tMax, 0.0f, false, 0.0f, false, hit))
                          hits[i] = CpuHit{hit.t, hit.from, hit.normal};
                        else
                          hits[i].reset();
                      }
                    });
}

}  // namespace iso::viewer
