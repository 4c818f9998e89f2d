// Point set surfaces ray traced on the GPU (shaders/pss.comp.glsl: an invocation a pixel through
// shaders/pss_trace.h, the source tracer/pss.cpp runs on the CPU): the surface's points,
// patches and grid uploaded once, a picture a call.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "shaders/shared.h"

#include "tracer/pss.h"
#include "viewer/vulkan.h"

namespace iso::viewer {

// A point set surface's and its volume's buffers on a device, in the order of
// shaders/pss_buffers.h's bindings (one-word placeholders where there is none).
class PssBuffers {
 public:
  // The surface (none: placeholders) and its points' linear colors (one a point, or none).
  PssBuffers(Gpu& gpu, const PssSurface* surface, const std::vector<glm::vec3>& colors);
  // The volume to read (none: placeholders); uploaded when it changes (after the device is idle).
  void setVolume(const PssVolume* volume);
  std::array<const Buffer*, gpu::kPssStorageBindings> storage() const;
  // The surface's and the volume's part of the parameters: the grid, the fit's settings, the
  // colors bit, the volume's grid and settings and the transfer function (throws
  // iso::UsageError for more points than PssParams holds).
  void fill(gpu::PssParams& q, const std::vector<PssTransferPoint>& transfer) const;
  uint64_t memoryBytes() const;  // device memory of its buffers

 private:
  Gpu& gpu_;
  const PssSurface* surface_;
  bool colors_ = false;
  Buffer positions_, normals_, colorBuffer_, patches_, pointStart_, points_, reachStart_, reach_;
  const PssVolume* volume_ = nullptr;
  Buffer volumeStart_, volumeOrder_, volumePoints_;
};

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
  PssBuffers buffers_;
  ComputePipeline pipeline_;
  Buffer params_, pixels_;
  Owned<VkQueryPool> queries_;
  VkCommandBuffer cb_ = VK_NULL_HANDLE;
  Owned<VkFence> fence_;
};

}  // namespace iso::viewer
