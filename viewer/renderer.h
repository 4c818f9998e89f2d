// The GPU side of the viewer: the page pool and tables in device memory under a budget, the
// uploads of streamed chunks, and the trace dispatch, with frames in flight (specs/viewer.md,
// "Frames in flight").
//
// A frame lives in one of `framesInFlight` slots, each with its command buffer, fence, timestamp
// queries, parameters, chunk table, feedback buffer and region of the staging buffer. prepare()
// takes the next slot (waiting for the frame that held it and collecting that frame's feedback),
// places decoded chunks, stages their words in the slot's region and writes the slot's
// parameters and table; record() records the copies and the dispatch into the slot's command
// buffer; submit() sends it. The host never waits for the frame just submitted: it waits only
// when a slot is needed again. Pages of evicted chunks are reused only once the frames that may
// still read them have completed (ChunkCache::gpuProgress).
//
// Threading: one thread calls everything here.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "viewer/asset.h"
#include "tracer/cpu_tracer.h"
#include "base/image.h"
#include "viewer/pss_gpu.h"
#include "viewer/streaming.h"
#include "viewer/vulkan.h"

namespace iso::viewer {

inline constexpr uint32_t kMaxFramesInFlight = 3;

struct RendererOptions {
  uint32_t width = 1024, height = 1024;
  uint32_t capacityWidth = 0, capacityHeight = 0;  // the largest size resize() allows (0: this)
  uint64_t vram = uint64_t(1) << 30;               // all device memory the viewer allocates
  uint64_t uploadBytes = 16u << 20;                // chunk bytes uploaded per frame at most
  uint32_t framesInFlight = 2;                     // 1 to kMaxFramesInFlight
  bool swapRedBlue = false;                        // BGRA output (swapchains)
  bool streaming = true;                           // rays request chunks; off: the top chunk alone
  bool flatTraversal = false;                      // the tracer's loop shape (shaders/rays.h)
  bool tileCones = true;  // camera rays start where their tile's cone meets a node (cone.h)
  // Frames of one sample a pixel whose hits leave no refracted rays run as a wavefront: the camera
  // rays, then the hits' shading and shadow rays side by side, then, bounce after bounce, the
  // mirror rays and their hits' shading (trace.comp.glsl); others as one kernel. With oneKernel
  // every frame runs as one kernel (for measurements).
  bool oneKernel = false;
  uint32_t workgroupSize = 64;  // invocations a workgroup: a power of two, 8 to 1024
  // Caustics: the caustic map and the photon pass exist (frames that ask for caustics without
  // them are drawn without).
  bool caustics = false;
  // A point set surface in the scene (and the volume inside it), in the file's frame units: every
  // frame meets it (kOptionPss). It must outlive the renderer.
  const PssObject* pss = nullptr;
};

// One frame, as collected once it completed.
struct FrameStats {
  uint64_t frame = 0;
  RayCounts rays;               // traced in the frame
  uint32_t requested = 0;       // chunks the frame's rays asked for that its table lacked
  uint32_t uploadedChunks = 0;  // placed in this frame
  uint64_t uploadedBytes = 0;
  uint64_t streamedBytes = 0;  // since the start, up to this frame
  uint32_t evicted = 0;
  uint32_t resident = 0;       // now, when collected
  bool twoPasses = false;      // drawn as a wavefront (RendererOptions::oneKernel)
  uint32_t mirrorBounces = 0;  // of the wavefront: passes of mirror rays
  uint32_t pending = 0;        // asked for, not resident yet
  uint64_t vramInUse = 0, vramPeak = 0, poolBytes = 0, poolBytesInUse = 0;
  double gpuSeconds = 0;            // copies and dispatch, from timestamps (0 without them)
  double dispatchSeconds = 0;  // the dispatches (photons too), from timestamps (0 without them)
  double gpuStart = 0, gpuEnd = 0;  // the device's clock at the frame's start and end (seconds)
  // Caustic photons traced in the frame (the frames whose lights, material, ground, level of
  // detail or resident chunks changed recompute the caustic map), and their pass's GPU time.
  uint64_t photons = 0;
  double photonSeconds = 0;
  std::chrono::steady_clock::time_point completed;  // when the host saw it done
};

class Renderer {
 public:
  Renderer(Gpu& gpu, const Asset& asset, const Environment* environment, RendererOptions options);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Draw at another size, up to the capacity asked for (a failed check beyond). Waits for the
  // frames in flight.
  void resize(uint32_t width, uint32_t height);

  // Host work of the next frame, in the next slot. params come from frameParams() without the
  // pool fields (set here).
  void prepare(gpu::FrameParams params);
  // The prepared frame's command buffer, begun, with the copies and the dispatch recorded; the
  // caller may record more (a copy of output() into a swapchain image) before submit().
  VkCommandBuffer record();
  // End and submit the prepared frame: waits on `wait` at `waitStage` when given, signals
  // `signal` when given, and the slot's fence.
  void submit(VkSemaphore wait = VK_NULL_HANDLE, VkPipelineStageFlags waitStage = 0,
              VkSemaphore signal = VK_NULL_HANDLE);
  // Wait for the oldest frame in flight and collect its feedback; false when none is in flight.
  bool collectNext();
  // Wait for every frame in flight and collect them: output() then holds the last one.
  void finish();
  // Called with each frame's stats as it is collected, in frame order.
  void onCollected(std::function<void(const FrameStats&)> callback) {
    onCollected_ = std::move(callback);
  }

  const Buffer& output() const { return output_; }  // RGBA8 (BGRA with swapRedBlue) pixels
  // A copy of the output: the last frame submitted (this waits for it).
  std::vector<uint32_t> pixels();
  // The last frame collected.
  const FrameStats& stats() const { return stats_; }
  // Whether the last collected frame's rays found every chunk they asked for, and nothing waits.
  bool converged() const { return stats_.requested == 0 && stats_.pending == 0; }
  // Whether streaming can make no more progress (what rays ask for does not fit the budget).
  bool stalled() const { return stalledFrames_ >= 3; }
  const FrameSetup& setup() const { return setup_; }
  uint32_t framesInFlight() const { return uint32_t(slots_.size()); }
  uint32_t inFlight() const { return uint32_t(inFlight_.size()); }
  // The slot of the prepared frame (callers keep per-slot semaphores by it).
  uint32_t slot() const { return current_; }
  // The last frame prepared (numbered from 1).
  uint32_t frameNumber() const { return frame_; }
  bool hasTimestamps() const { return queries_.get() != VK_NULL_HANDLE; }

 private:
  struct Copy {
    uint32_t buffer;
    VkBufferCopy region;
  };
  struct Slot {
    VkCommandBuffer cb = VK_NULL_HANDLE;
    Owned<VkFence> fence;
    Buffer params, table, feedback, timestamps;
    Buffer pssParams;  // the point set surface's (PssObject::params), or a placeholder
    VkDescriptorSet set = VK_NULL_HANDLE;
    bool wavefront = false;  // the prepared frame runs as a wavefront
    uint32_t photons = 0;    // the prepared frame recomputes the caustic map with these photons
    uint64_t stagingOffset = 0;
    std::vector<Copy> copies;
    FrameStats stats;  // what prepare() knows of the slot's frame
  };
  void createSlots(uint64_t stagingRegion);
  void writeDescriptors(const Slot& slot);
  void recordWavefront(VkCommandBuffer cb, uint32_t tiles, uint32_t bounces);
  void recordCones(VkCommandBuffer cb, uint32_t tiles);
  uint32_t waveTiles_ = 0;  // tiles a wave of a wavefront frame (its hits fit hits_)
  void stage(Slot& slot);
  void collect(Slot& slot);
  void readTimestamps(const Slot& slot, FrameStats& stats) const;

  Gpu& gpu_;
  const Asset& asset_;
  RendererOptions options_;
  FrameSetup setup_;
  ComputePipeline pipeline_;
  // By the shader's kPass and kSplats: its pipeline in pipeline_ (the splat kernels exist when the
  // file keeps points).
  std::array<std::array<uint32_t, 2>, 6> pipelineIndex_{};
  bool splatsDrawn_ = false;  // the frame being recorded meets splats (kOptionSplats)
  VkPipeline pipelineOf(uint32_t pass) const {
    return pipeline_.pipelines[pipelineIndex_[pass][splatsDrawn_ ? 1 : 0]];
  }
  Buffer output_, environment_, staging_;
  Buffer hits_, queue_;     // the wavefront's hits to shade and its queue
  Buffer starts_;           // where each tile's camera rays start (shaders/cone.h)
  Buffer paths_, pending_;  // the wave's paths that reflect mirror rays, and the rays waiting
  Buffer caustics_;         // the caustic map (a word without RendererOptions::caustics)
  std::unique_ptr<PssBuffers> pss_;  // RendererOptions::pss's buffers, or placeholders
  // What the caustic map was last computed for: the frame parameters that photons depend on
  // (causticKey), and the resident chunks' version (bumped by each upload or eviction).
  std::vector<std::byte> causticKey_;
  uint64_t residentVersion_ = 0;
  void recordPhotons(VkCommandBuffer cb, uint32_t photons);
  std::vector<Buffer> pool_;
  uint32_t pagesPerBuffer_ = 0;
  std::unique_ptr<ChunkCache> cache_;
  std::vector<gpu::ChunkEntry> table_;  // the host's chunk table; each frame gets a copy
  std::vector<Slot> slots_;
  // 4 timestamps a slot: start, copies done, photons done, dispatch done.
  Owned<VkQueryPool> queries_;
  double timestampSeconds_ = 0;
  uint64_t timestampMask_ = 0;
  std::vector<uint32_t> inFlight_;  // slots submitted and not collected, oldest first
  uint32_t current_ = 0;            // the slot of the frame prepared last
  bool prepared_ = false;           // a frame is prepared and not yet submitted
  uint32_t frame_ = 0;
  uint64_t lastCollected_ = 0;
  uint64_t streamedBytes_ = 0;
  uint32_t stalledFrames_ = 0;
  FrameStats stats_;
  std::function<void(const FrameStats&)> onCollected_;
};

// A whole frame without a window: prepare, record, submit (the host does not wait for it).
void renderFrame(Renderer& renderer, const gpu::FrameParams& params);

}  // namespace iso::viewer
