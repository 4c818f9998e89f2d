// The CPU reference tracer: the shaders' tracing code (shaders/trace.h) compiled as C++ and run
// over every pixel with TBB, on the whole file resident. Golden tests compare the GPU's pictures
// with its pictures; it is also `iso view --cpu`, and it traces the rays of the visibility
// measure (pipeline/visibility.h), so that what is measured is what the viewer draws.
//
// Threading: a CpuPool is read-only once built; every function here may run from many threads.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "iso/reader.h"
#include "shaders/shared.h"
#include "tracer/blob.h"
#include "base/image.h"
#include "tracer/pss.h"

namespace iso::viewer {

// The surface chunks of a file as blobs in one host page pool, and the chunk table.
struct CpuPool {
  std::vector<uint32_t> words;
  std::vector<gpu::ChunkEntry> chunks;
  uint32_t topChunk = 0;  // the chunk holding the octree's root
  BlobOptions blob;       // what the corner records carry
  // With splats: the splat index's chunk (one past the file's chunks) and the typical radius.
  uint32_t splatIndex = kNoParent;
  float splatRadius = 0.0f;
  uint64_t splatPoints = 0, splatBytes = 0;  // in the points chunks' splat blobs (subsamples too)
  // A point set surface in the scene (kOptionPss), in the file's frame units; none: null.
  const PssObject* pss = nullptr;
};
// Every surface chunk, or those `holds` accepts (the others are not resident: a ray that needs
// one draws the coarser level, as the GPU does until it arrives). Throws iso::FileError for files
// whose payloads are damaged or that hold no surface.
// With `splats`, also the points chunks (those `holds` accepts) as splat blobs and the splat
// index, when the file keeps points.
using ChunkFilter = std::function<bool(const ChunkInfo&)>;
CpuPool buildCpuPool(const Reader& reader, const ChunkFilter& holds = {}, bool splats = false);

// Rays traced, by kind.
struct RayCounts {
  uint64_t primary = 0;    // camera rays
  uint64_t shadow = 0;     // toward lights
  uint64_t secondary = 0;  // reflected and refracted
  uint64_t total() const { return primary + shadow + secondary; }
  RayCounts& operator+=(const RayCounts& o) {
    primary += o.primary;
    shadow += o.shadow;
    secondary += o.secondary;
    return *this;
  }
};

struct CpuFrame {
  std::vector<uint32_t> pixels;  // RGBA8
  RayCounts rays;
  uint64_t photons = 0;  // caustic photons traced before the picture, and their time
  double photonSeconds = 0;
};

// Render a frame: with caustics on (params.caustics.x), the caustic map first. params.pool is
// ignored (the host pool is one array).
CpuFrame renderCpu(const CpuPool& pool, const gpu::FrameParams& params,
                   const Environment* environment);

// The caustic map of a frame's lights, material and ground (shaders/caustics.h): 3 words a cell
// (shared.h, kCausticCells), each the irradiance times kCausticScale; zeros with caustics off.
struct CausticMap {
  std::vector<uint32_t> words;
  uint64_t photons = 0;  // traced
  double seconds = 0;
};
CausticMap causticMapCpu(const CpuPool& pool, const gpu::FrameParams& params);

// Where the camera rays of the pixels [x0, x1) × [y0, y1) start in renderCpu: the start of the
// tile's cone (shaders/cone.h), 1e30 where it meets nothing, 0 with tile cones off.
float tileStartCpu(const CpuPool& pool, const gpu::FrameParams& params, uint32_t x0, uint32_t y0,
                   uint32_t x1, uint32_t y1);

// Parameters under which rays see the finest leaves everywhere (no coarser level of detail is
// drawn) and nothing is shaded: for tracing single rays.
gpu::FrameParams finestFrameParams(const CpuPool& pool);

// The same with the splats drawn (the pool's points; `surfaceToo`: and the surface, the nearer
// hit), at their finest, blended as the viewer blends them.
gpu::FrameParams splatFrameParams(const CpuPool& pool, bool surfaceToo);

// The first hit of one ray (frame units) with the tracer's rules (trace.h, traceScene; the
// surface's: intersect):
// `side` 0 takes a crossing either way, as camera rays do; +1 or -1 is the side a ray leaving a
// surface starts on; `strict` keeps that rule past empty cells (back faces hidden).
struct CpuHit {
  float t = 0;
  float from = 1;      // the side the ray came from: +1 a front face, -1 a back face
  glm::vec3 normal{};  // unit, pointing outside
};
std::optional<CpuHit> traceCpu(const CpuPool& pool, const gpu::FrameParams& params,
                               glm::vec3 origin, glm::vec3 direction, float side = 0.0f,
                               bool strict = false);

// Many rays at once (in parallel): hits[i] is ray i's first hit with t in [tMin, tMax], side 0.
struct CpuRay {
  glm::vec3 origin{}, direction{};
  float tMin = 0.0f, tMax = 1e30f;
};
void traceCpu(const CpuPool& pool, const gpu::FrameParams& params, std::span<const CpuRay> rays,
              std::span<std::optional<CpuHit>> hits);

}  // namespace iso::viewer
