// Image-space point rendering on the GPU: shaders/image.comp.glsl's stages recorded in the order
// the CPU reference (point_image.h) runs them, over the same plan (planImage), so that the two
// draw the same pictures (specs/viewer.md, "Image-space points").
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "tracer/point_image.h"
#include "viewer/vulkan.h"

namespace iso::viewer {

// Lavapipe pays about a millisecond for an empty dispatch, so filling rounds go to the GPU two
// at a time and the host stops when one changed nothing (specs/viewer.md, "Image-space points").
inline constexpr int kFillRoundsPerSubmit = 2;

// The steps of a frame on the GPU, as its timestamps count them (GpuImageFrame::stepSeconds).
enum class ImageStep : uint8_t {
  Wait,  // the GPU between two submits: the host looked at the filling's counts
  Clear, Project, Fill, Control, Shade,
  Smooth,  // smoothing, anti-aliasing and blending (one stage)
  Lit,
  Count
};
inline constexpr std::array<const char*, size_t(ImageStep::Count)> kImageStepNames = {
    "wait", "clear", "project", "fill", "control", "shade", "smooth+aa", "lit"};

// GPU bytes of a point (position, normal and color, a vec4 each), of its shadow texture for one
// light, of a pixel's layers (the eye's or a light's image: the two filling alternates, the
// first also holding the projection's keys, and the previous layer, 8 bytes each) and of a
// pixel of the eye's picture (the shaded and the blended colors, and the sRGB word).
inline constexpr uint64_t kImagePointBytes = 48, kImageLitBytes = 4;
inline constexpr uint64_t kImageLayerPixelBytes = 24, kImagePicturePixelBytes = 36;

// What fits in `vram` bytes for a picture of width × height: the points drawn (all `points`, or a
// subsample of at most three quarters of what is left after the picture) and the lights' images'
// largest size across (what is left after the points).
struct ImageBudget {
  uint64_t points = 0;
  int shadowResolution = 4096;
};
ImageBudget imageBudget(uint64_t vram, uint64_t points, uint32_t width, uint32_t height,
                        size_t lights);

struct GpuImageFrame {
  std::vector<uint32_t> pixels;  // sRGB8 RGBA words, row after row
  ImageStats stats;
  double gpuSeconds = 0.0;       // the frame's steps, from timestamps (0 without them), waits out
  std::array<double, size_t(ImageStep::Count)> stepSeconds{};  // each kind of step, summed
  int submits = 0;               // command buffers submitted (filling waits for its counts)
};

class GpuPointImage {
 public:
  // Uploads the scene's points; UsageError when the device lacks 64-bit buffer atomics.
  GpuPointImage(Gpu& gpu, const PointImageScene& scene);
  ~GpuPointImage();
  GpuPointImage(const GpuPointImage&) = delete;
  GpuPointImage& operator=(const GpuPointImage&) = delete;

  // Draws one frame and waits for it.
  GpuImageFrame render(const ImageCamera& camera, std::span<const ImageLight> lights,
                       const ImageSettings& settings);

  // Draws another scene's points from now on (uploaded; the pipelines stay).
  void setScene(const PointImageScene& scene);

  uint64_t memoryBytes() const;  // device memory of its buffers
  // Filling rounds recorded between two looks at their counts (default kFillRoundsPerSubmit).
  void setRoundsPerSubmit(int rounds) { roundsPerSubmit_ = std::max(rounds, 1); }

 private:
  void prepare(const ImagePlan& plan, size_t lights);  // buffers and sets sized for the plan

  Gpu& gpu_;
  const PointImageScene* scene_;
  ComputePipeline pipeline_;
  Buffer positions_, normals_, colors_;
  Buffer params_, layerA_, layerB_, layerR_, colorA_, blended_, lit_, control_,
      pixels_, tiles_;
  Owned<VkQueryPool> queries_;
  VkCommandBuffer cb_ = VK_NULL_HANDLE;
  Owned<VkFence> fence_;
  size_t sets_ = 0, pixelCapacity_ = 0, eyePixels_ = 0, litCapacity_ = 0, tileCapacity_ = 0;
  std::vector<float> shadowKey_;
  int roundsPerSubmit_ = kFillRoundsPerSubmit;
  bool pointsChanged_ = false;  // the descriptor sets name the old point buffers
};

}  // namespace iso::viewer
