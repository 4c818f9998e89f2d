// Point set surfaces ray traced on the GPU (shaders/pss.comp.glsl: an invocation a pixel through
// shaders/pss_trace.h, the source viewer/pss.cpp runs on the CPU): the surface's points,
// patches and grid uploaded once, a picture a call.
#pragma once

#include <cstdint>
#include <vector>

#include "viewer/pss.h"
#include "viewer/vulkan.h"

namespace iso::viewer {

class GpuPss {
 public:
  // Uploads the surface (and the points' linear colors, one a point, or none).
  GpuPss(Gpu& gpu, const PssSurface& surface, const std::vector<glm::vec3>& colors);
  ~GpuPss();
  GpuPss(const GpuPss&) = delete;
  GpuPss& operator=(const GpuPss&) = delete;

  // The picture (sRGB8 RGBA words, rows from the top), drawn and waited for; its GPU time in
  // seconds (timestamps) in *gpuSeconds when asked and the device has them.
  std::vector<uint32_t> render(const PssRender& render, double* gpuSeconds = nullptr);
  uint64_t memoryBytes() const;  // device memory of its buffers

 private:
  Gpu& gpu_;
  const PssSurface& surface_;
  bool colors_ = false;
  ComputePipeline pipeline_;
  Buffer params_, positions_, normals_, colorBuffer_, patches_, pointStart_, points_,
      reachStart_, reach_, pixels_;
  // The volume last drawn (its buffers), none: one-word placeholders.
  const PssVolume* volume_ = nullptr;
  Buffer volumeStart_, volumeOrder_, volumePoints_;
  Owned<VkQueryPool> queries_;
  VkCommandBuffer cb_ = VK_NULL_HANDLE;
  Owned<VkFence> fence_;
};

}  // namespace iso::viewer
