// The GPU side of the viewer: the page pool and tables in device memory under a budget, the
// uploads of streamed chunks, and the trace dispatch (specs/viewer.md, "Frames").
//
// A frame is prepare() (host: place decoded chunks, stage their words, write the parameters),
// record() (copies, then the dispatch into the output buffer), a submit and wait by the caller,
// then collect() (host: read the rays' requests and use marks). One frame is in flight at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "viewer/asset.h"
#include "viewer/cpu_tracer.h"
#include "viewer/image.h"
#include "viewer/streaming.h"
#include "viewer/vulkan.h"

namespace iso::viewer {

struct RendererOptions {
  uint32_t width = 1024, height = 1024;
  uint32_t capacityWidth = 0, capacityHeight = 0;  // the largest size resize() allows (0: this)
  uint64_t vram = uint64_t(1) << 30;               // all device memory the viewer allocates
  uint64_t uploadBytes = 16u << 20;                // chunk bytes uploaded per frame at most
  bool swapRedBlue = false;                        // BGRA output (swapchains)
  bool streaming = true;                           // rays request chunks; off: the top chunk alone
  bool flatTraversal = false;                      // the tracer's loop shape (shaders/rays.h)
  uint32_t workgroupSize = 64;  // invocations a workgroup: a power of two, 8 to 1024
};

struct FrameStats {
  uint64_t frame = 0;
  RayCounts rays;               // traced in the frame
  uint32_t requested = 0;       // chunks rays asked for that were not resident
  uint32_t uploadedChunks = 0;  // placed in this frame
  uint64_t uploadedBytes = 0;
  uint64_t streamedBytes = 0;  // since the start
  uint32_t evicted = 0;
  uint32_t resident = 0;
  uint32_t pending = 0;  // asked for, not resident yet
  uint64_t vramInUse = 0, vramPeak = 0, poolBytes = 0, poolBytesInUse = 0;
};

class Renderer {
 public:
  Renderer(Gpu& gpu, const Asset& asset, const Environment* environment, RendererOptions options);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Draw at another size, up to the capacity asked for (a failed check beyond).
  void resize(uint32_t width, uint32_t height);

  // Host work of a frame. params come from frameParams() without the pool fields (set here).
  void prepare(gpu::FrameParams params);
  void record(VkCommandBuffer cb);
  void collect();

  const Buffer& output() const { return output_; }  // RGBA8 (BGRA with swapRedBlue) pixels
  std::vector<uint32_t> pixels() const;             // a copy of the output
  const FrameStats& stats() const { return stats_; }
  // Whether the last frame's rays found every chunk they asked for resident.
  bool converged() const { return stats_.requested == 0 && stats_.pending == 0; }
  // Whether streaming can make no more progress (what rays ask for does not fit the budget).
  bool stalled() const { return stalledFrames_ >= 3; }
  const FrameSetup& setup() const { return setup_; }
  uint32_t frameNumber() const { return frame_; }

 private:
  Gpu& gpu_;
  const Asset& asset_;
  RendererOptions options_;
  FrameSetup setup_;
  ComputePipeline pipeline_;
  Buffer params_, chunkTable_, feedback_, output_, environment_, staging_;
  std::vector<Buffer> pool_;
  uint32_t pagesPerBuffer_ = 0;
  std::unique_ptr<ChunkCache> cache_;
  struct Copy {
    uint32_t buffer;
    VkBufferCopy region;
  };
  std::vector<Copy> copies_;
  uint32_t frame_ = 0;
  uint32_t stalledFrames_ = 0;
  FrameStats stats_;
};

// Submit one command buffer and wait for it.
void submitAndWait(Gpu& gpu, VkCommandBuffer cb, VkFence fence);

// A whole frame: prepare, record into cb, submit and wait on fence, collect. Returns the seconds
// from submit to done.
double renderFrame(Gpu& gpu, Renderer& renderer, const gpu::FrameParams& params, VkCommandBuffer cb,
                   VkFence fence);

}  // namespace iso::viewer
