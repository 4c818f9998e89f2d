// What the GPU drivers of `iso view` share (view.cpp, bench.cpp): the asset and its scene, a
// device and a renderer, made from the command's options.
#pragma once

#include <memory>
#include <optional>

#include "viewer/asset.h"
#include "viewer/renderer.h"
#include "viewer/view.h"

namespace iso::viewer {

std::optional<Environment> environmentOf(const Scene& scene);

struct GpuView {
  std::unique_ptr<Asset> asset;
  std::shared_ptr<const PssObject> pssObject;  // ViewOptions::pss, kept for the renderer
  const PssObject* pss = nullptr;
  Scene scene;
  std::optional<Environment> env;
  Gpu gpu;  // outlives what is made from it (members are destroyed in reverse order)
  Renderer renderer;

  // A renderer with framesInFlight slots and the options' size, budget and uploads.
  GpuView(const ViewOptions& options, uint32_t framesInFlight);
  // The shaders' parameters of a frame of `s`.
  gpu::FrameParams params(const Scene& s) const;
};

}  // namespace iso::viewer
