// `iso view`: the drivers behind the command (tools/iso/cmd_view.cpp) — a window, a headless
// picture (GPU or CPU reference tracer), and a benchmark along a camera path (bench.cpp).
#pragma once

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "viewer/scene.h"

namespace iso::viewer {

struct PssObject;

struct ViewOptions {
  std::filesystem::path file;
  std::filesystem::path sceneFile;  // JSON scene (watched and reloaded in the window)
  Scene scene;                      // after the scene file and the command line
  uint32_t width = 1024, height = 1024;
  uint64_t vram = uint64_t(1) << 30;
  uint64_t uploadBytes = 16u << 20;
  uint32_t framesInFlight = 2;  // window and benchmark; --headless renders a frame at a time
  bool validation = false;
  std::string device;
  // Headless
  std::filesystem::path out;
  uint32_t maxFrames = 1000;  // frames to let streaming converge
  // Window
  uint32_t frames = 0;               // quit after this many frames (0: when closed)
  std::filesystem::path screenshot;  // save the last frame here when quitting
  // Benchmark
  uint32_t benchFrames = 120;
  // The tracer's loop shape and workgroup size (measured in specs/viewer.md).
  bool flatTraversal = false;
  bool tileCones = true;  // camera rays start where their tile's cone meets a node (cone.h)
  uint32_t workgroupSize = 64;
  // RendererOptions::oneKernel: one kernel, or the wavefront; neither named: one kernel on a GPU,
  // the wavefront on a CPU device (lavapipe), the faster of the two on each (specs/viewer.md).
  bool oneKernel = false;
  bool wavefront = false;
  bool cpuCompare = true;  // also trace the first view with the CPU reference tracer
  bool benchJson = false;  // print the numbers as one JSON object instead of text
  // A point set surface in the scene beside the file's surface and splats (--with-pss), in the
  // file's frame units, and the volume inside it.
  std::shared_ptr<const PssObject> pss;
};

// The picture's width / height.
inline double aspectOf(const ViewOptions& o) {
  return double(o.width) / double(std::max(o.height, 1u));
}

struct Asset;
struct Gpu;
// The Vulkan device the options name (--device, --validation).
Gpu gpuFor(const ViewOptions& options);
// The options' scene with a camera (the default view of the asset, defaultCamera, when it has
// none) and lights (one over the camera's shoulder when it has none).
Scene completeScene(const ViewOptions& options, const Asset& asset);
// The camera a view starts at, and the window's Home key goes back to: the options' camera, or
// the default view of the asset for a picture of this aspect (width / height).
Camera startCamera(const ViewOptions& options, const Asset& asset, double aspect);
// A ground asked for without a height (Scene::groundAuto, or caustics without a ground) placed
// just under the asset's bounds.
void placeGround(Scene& scene, const Asset& asset);

// Each returns the process exit code and throws for errors (file, Vulkan, options).
int viewHeadless(const ViewOptions& options);
int viewCpu(const ViewOptions& options);
int viewBench(const ViewOptions& options);
struct ImageInputs;
struct ImageViewOptions;
// The window's image-space mode (key K after surface, points and both; image_view.h): the .iso
// file's kept points, read the first time the mode is asked for (an error, for a file that keeps
// none, leaves the window as it was), drawn with `options`. Without `read`, K has three steps.
struct WindowImageMode {
  std::function<std::shared_ptr<const ImageInputs>()> read;
  std::shared_ptr<const ImageViewOptions> options;
};
int viewWindow(const ViewOptions& options, const WindowImageMode& image = {});

}  // namespace iso::viewer
