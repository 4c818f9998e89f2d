// Headless pictures and the CPU reference picture of `iso view` (view.h); the benchmark is
// bench.cpp.
#include "viewer/view.h"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>

#include "iso/error.h"
#include "base/text.h"
#include "viewer/asset.h"
#include "tracer/cpu_tracer.h"
#include "viewer/gpu_view.h"
#include "base/image.h"
#include "viewer/renderer.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// The caustic photons of a picture's last caustic map: how many, in how long (`where`).
void printPhotons(uint64_t photons, double seconds, const char* where) {
  fmt::print("  caustics: {} photons in {:.1f} ms {} ({:.2f} Mphotons/s)\n", photons,
             seconds * 1e3, where, seconds > 0 ? photons / seconds / 1e6 : 0.0);
}

RendererOptions rendererOptions(const ViewOptions& o, uint32_t framesInFlight, const Gpu& gpu) {
  RendererOptions r;
  r.width = o.width;
  r.height = o.height;
  r.vram = o.vram;
  r.uploadBytes = o.uploadBytes;
  r.flatTraversal = o.flatTraversal;
  r.tileCones = o.tileCones;
  r.workgroupSize = o.workgroupSize;
  r.oneKernel = o.oneKernel ||
                (!o.wavefront && gpu.properties.deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU);
  r.framesInFlight = framesInFlight;
  r.caustics = o.scene.caustics > 0;
  r.pss = o.pss.get();
  return r;
}

}  // namespace

Gpu gpuFor(const ViewOptions& o) {
  GpuOptions g;
  g.validation = o.validation;
  g.deviceName = o.device;
  return createGpu(g);
}

std::optional<Environment> environmentOf(const Scene& scene) {
  if (scene.environment.empty()) return std::nullopt;
  return loadEnvironment(scene.environment);
}

GpuView::GpuView(const ViewOptions& o, uint32_t framesInFlight)
    : asset(Asset::open(o.file)),
      pssObject(o.pss),
      pss(o.pss.get()),
      scene(completeScene(o, *asset)),
      env(environmentOf(scene)),
      gpu(gpuFor(o)),
      renderer(gpu, *asset, env ? &*env : nullptr, rendererOptions(o, framesInFlight, gpu)) {}

gpu::FrameParams GpuView::params(const Scene& s) const {
  const FileHeader& header = asset->reader.header();
  return frameParams(s, header.frame, header.maxLevel, renderer.setup());
}

void placeGround(Scene& scene, const Asset& asset) {
  if (scene.caustics > 0 && !scene.groundHeight) scene.groundAuto = true;  // caustics land there
  if (!scene.groundAuto || scene.groundHeight || !scene.camera) return;
  // Under the lowest corner of the bounds along up.
  const Vec3d u = normalized(scene.up.value_or(scene.camera->up));
  double lowest = 1e300;
  for (int k = 0; k < 8; ++k) {
    const Vec3d corner((k & 1) ? asset.bounds.hi[0] : asset.bounds.lo[0],
                       (k & 2) ? asset.bounds.hi[1] : asset.bounds.lo[1],
                       (k & 4) ? asset.bounds.hi[2] : asset.bounds.lo[2]);
    lowest = std::min(lowest, glm::dot(u, corner));
  }
  scene.groundHeight = lowest;
}

Camera startCamera(const ViewOptions& options, const Asset& asset, double aspect) {
  const Scene& scene = options.scene;
  if (scene.camera) {
    Camera camera = *scene.camera;
    if (scene.fovDegrees) camera.fovDegrees = *scene.fovDegrees;
    return camera;
  }
  return defaultCamera(asset.cells, scene.up.value_or(asset.up), scene.fovDegrees.value_or(40.0),
                       aspect);
}

Scene completeScene(const ViewOptions& options, const Asset& asset) {
  Scene scene = options.scene;
  if (scene.draw != Draw::Surface && !asset.splats)
    throw FileError(asset.reader.name(), std::nullopt,
                    "the file keeps no points to draw as splats (convert with --keep-points)");
  scene.camera = startCamera(options, asset, aspectOf(options));
  if (scene.lights.empty()) scene.lights.push_back(defaultLight(*scene.camera, asset.bounds));
  placeGround(scene, asset);
  return scene;
}

int viewHeadless(const ViewOptions& options) {
  // One frame at a time: a view converging needs each frame's requests before the next frame,
  // so frames in flight would only delay the chunks it asks for.
  GpuView view(options, 1);
  Gpu& gpu = view.gpu;
  Renderer& renderer = view.renderer;
  const Asset* asset = view.asset.get();
  const auto start = Clock::now();
  double lastFrame = 0;
  uint32_t frames = 0;
  std::pair<uint64_t, double> lastPhotons{0, 0.0};  // of the last frame that traced them
  for (; frames < options.maxFrames; ++frames) {
    const auto t0 = Clock::now();
    renderFrame(renderer, view.params(view.scene));
    renderer.finish();
    if (renderer.stats().photons > 0)
      lastPhotons = {renderer.stats().photons, renderer.stats().photonSeconds};
    lastFrame = seconds(Clock::now() - t0);
    if (renderer.converged() || renderer.stalled()) {
      ++frames;
      break;
    }
  }
  const FrameStats& s = renderer.stats();
  const auto pixels = renderer.pixels();
  const auto [photons, photonSeconds] = lastPhotons;
  writeRgba8Image(options.out, options.width, options.height, pixels);
  fmt::print("{}: {}x{} on {}, {} frame{} in {:.2f} s ({}), last frame {:.1f} ms, {:.1f} Mrays/s\n",
             options.out.string(), options.width, options.height, gpu.properties.deviceName, frames,
             frames == 1 ? "" : "s", seconds(Clock::now() - start),
             renderer.converged() ? "converged" : "not converged", lastFrame * 1e3,
             lastFrame > s.photonSeconds ? s.rays.total() / (lastFrame - s.photonSeconds) / 1e6
                                         : 0.0);
  fmt::print(
      "  chunks {} resident of {}, pool {} of {}, streamed {}, GPU memory {} at most "
      "(--vram {})\n",
      s.resident, asset->reader.chunks().size(), byteSize(s.poolBytesInUse), byteSize(s.poolBytes),
      byteSize(s.streamedBytes), byteSize(s.vramPeak), byteSize(options.vram));
  if (photons > 0) printPhotons(photons, photonSeconds, "on the GPU");
  if (renderer.stalled())
    fmt::print(stderr,
               "iso view: the view needs more chunks than --vram {} holds; coarser levels are "
               "shown where they are missing\n",
               byteSize(options.vram));
  if (*gpu.validationErrors > 0) {
    fmt::print(stderr, "iso view: {} Vulkan validation errors\n", gpu.validationErrors->load());
    return 1;
  }
  return 0;
}

int viewCpu(const ViewOptions& options) {
  const auto asset = Asset::open(options.file);
  const Scene scene = completeScene(options, *asset);
  const auto env = environmentOf(scene);
  const auto t0 = Clock::now();
  CpuPool pool = buildCpuPool(asset->reader, {}, scene.draw != Draw::Surface);
  pool.pss = options.pss.get();
  const double load = seconds(Clock::now() - t0);
  FrameSetup setup = cpuFrameSetup(*asset, options.width, options.height, env ? &*env : nullptr);
  setup.flatTraversal = options.flatTraversal;
  setup.tileCones = options.tileCones;
  setup.pss = pool.pss != nullptr;
  const auto params =
      frameParams(scene, asset->reader.header().frame, asset->reader.header().maxLevel, setup);
  const auto t1 = Clock::now();
  const CpuFrame frame = renderCpu(pool, params, env ? &*env : nullptr);
  const double render = seconds(Clock::now() - t1);
  writeRgba8Image(options.out, options.width, options.height, frame.pixels);
  fmt::print(
      "{}: {}x{} on the CPU reference tracer, {:.2f} s ({:.1f} Mrays/s), chunks decoded in "
      "{:.2f} s\n",
      options.out.string(), options.width, options.height, render,
      frame.rays.total() / std::max(render - frame.photonSeconds, 1e-9) / 1e6, load);
  if (frame.photons > 0) printPhotons(frame.photons, frame.photonSeconds, "on the CPU");
  return 0;
}

}  // namespace iso::viewer
