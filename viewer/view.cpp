// Headless pictures, the CPU reference picture and the benchmark of `iso view` (view.h).
#include "viewer/view.h"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>

#include "pipeline/base/text.h"
#include "viewer/asset.h"
#include "viewer/cpu_tracer.h"
#include "viewer/image.h"
#include "viewer/renderer.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

std::optional<Environment> environmentOf(const Scene& scene) {
  if (scene.environment.empty()) return std::nullopt;
  return loadEnvironment(scene.environment);
}

Gpu gpuFor(const ViewOptions& o) {
  GpuOptions g;
  g.validation = o.validation;
  g.deviceName = o.device;
  return createGpu(g);
}

RendererOptions rendererOptions(const ViewOptions& o) {
  RendererOptions r;
  r.width = o.width;
  r.height = o.height;
  r.vram = o.vram;
  r.uploadBytes = o.uploadBytes;
  r.flatTraversal = o.flatTraversal;
  r.workgroupSize = o.workgroupSize;
  return r;
}

// What the GPU modes share: the asset and its scene, a device, a renderer, and the command
// buffer and fence of a frame.
struct GpuView {
  std::unique_ptr<Asset> asset;
  Scene scene;
  std::optional<Environment> env;
  Gpu gpu;  // outlives what is made from it (members are destroyed in reverse order)
  Renderer renderer;
  VkCommandBuffer cb;
  Owned<VkFence> fence;

  explicit GpuView(const ViewOptions& o)
      : asset(Asset::open(o.file)),
        scene(completeScene(o, *asset)),
        env(environmentOf(scene)),
        gpu(gpuFor(o)),
        renderer(gpu, *asset, env ? &*env : nullptr, rendererOptions(o)),
        cb(allocateCommandBuffer(gpu)),
        fence(createFence(gpu, false)) {}
  // Render a frame of `s` and wait for it; the seconds from submit to done.
  double frame(const Scene& s) {
    const FileHeader& header = asset->reader.header();
    return renderFrame(gpu, renderer,
                       frameParams(s, header.frame, header.maxLevel, renderer.setup()), cb, fence);
  }
};

}  // namespace

Scene completeScene(const ViewOptions& options, const Asset& asset) {
  Scene scene = options.scene;
  const Vec3d up = scene.up.value_or(asset.up);
  if (!scene.camera) scene.camera = frameCamera(asset.bounds, up, scene.fovDegrees.value_or(40.0));
  if (scene.fovDegrees) scene.camera->fovDegrees = *scene.fovDegrees;
  if (scene.lights.empty()) scene.lights.push_back(defaultLight(*scene.camera, asset.bounds));
  return scene;
}

int viewHeadless(const ViewOptions& options) {
  GpuView view(options);
  Gpu& gpu = view.gpu;
  Renderer& renderer = view.renderer;
  const Asset* asset = view.asset.get();
  const auto start = Clock::now();
  double lastFrame = 0;
  uint32_t frames = 0;
  for (; frames < options.maxFrames; ++frames) {
    lastFrame = view.frame(view.scene);
    if (renderer.converged() || renderer.stalled()) {
      ++frames;
      break;
    }
  }
  const FrameStats& s = renderer.stats();
  const auto pixels = renderer.pixels();
  writeImage(options.out, options.width, options.height, pixels);
  fmt::print("{}: {}x{} on {}, {} frame{} in {:.2f} s ({}), last frame {:.1f} ms, {:.1f} Mrays/s\n",
             options.out.string(), options.width, options.height, gpu.properties.deviceName, frames,
             frames == 1 ? "" : "s", seconds(Clock::now() - start),
             renderer.converged() ? "converged" : "not converged", lastFrame * 1e3,
             lastFrame > 0 ? s.rays.total() / lastFrame / 1e6 : 0.0);
  fmt::print(
      "  chunks {} resident of {}, pool {} of {}, streamed {}, GPU memory {} at most "
      "(--vram {})\n",
      s.resident, asset->reader.chunks().size(), byteSize(s.poolBytesInUse), byteSize(s.poolBytes),
      byteSize(s.streamedBytes), byteSize(s.vramPeak), byteSize(options.vram));
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
  const CpuPool pool = buildCpuPool(asset->reader);
  const double load = seconds(Clock::now() - t0);
  FrameSetup setup = cpuFrameSetup(*asset, options.width, options.height, env ? &*env : nullptr);
  setup.flatTraversal = options.flatTraversal;
  const auto params =
      frameParams(scene, asset->reader.header().frame, asset->reader.header().maxLevel, setup);
  const auto t1 = Clock::now();
  const CpuFrame frame = renderCpu(pool, params, env ? &*env : nullptr);
  const double render = seconds(Clock::now() - t1);
  writeImage(options.out, options.width, options.height, frame.pixels);
  fmt::print(
      "{}: {}x{} on the CPU reference tracer, {:.2f} s ({:.1f} Mrays/s), chunks decoded in "
      "{:.2f} s\n",
      options.out.string(), options.width, options.height, render,
      frame.rays.total() / render / 1e6, load);
  return 0;
}

int viewBench(const ViewOptions& options) {
  GpuView view(options);
  Gpu& gpu = view.gpu;
  Renderer& renderer = view.renderer;
  const Asset* asset = view.asset.get();
  const Scene& base = view.scene;
  // The camera path: a full orbit around the target at the starting distance.
  const Camera c0 = *base.camera;
  const Vec3d axis = normalized(c0.up), offset = c0.eye - c0.target;
  std::vector<double> ms;
  std::vector<uint64_t> uploaded;
  uint64_t rays = 0;
  double total = 0;
  uint32_t maxResident = 0;
  for (uint32_t f = 0; f < options.benchFrames; ++f) {
    const double a = 2 * M_PI * f / options.benchFrames;
    Scene scene = base;
    scene.camera->eye = c0.target + rotated(offset, axis, a);
    const double dt = view.frame(scene);
    const FrameStats& s = renderer.stats();
    if (f > 0) {  // the first frame builds the pipeline's caches
      ms.push_back(dt * 1e3);
      rays += s.rays.total();
      total += dt;
    }
    uploaded.push_back(s.uploadedBytes);
    maxResident = std::max(maxResident, s.resident);
  }
  const FrameStats& s = renderer.stats();
  std::vector<double> sorted = ms;
  std::sort(sorted.begin(), sorted.end());
  const double mean = std::accumulate(ms.begin(), ms.end(), 0.0) / std::max<size_t>(ms.size(), 1);
  const uint64_t upTotal = std::accumulate(uploaded.begin(), uploaded.end(), uint64_t(0));
  const uint64_t upMax = *std::max_element(uploaded.begin(), uploaded.end());
  fmt::print(
      "bench {}: {}x{} on {}, {} frames orbiting, samples {}, shadows {}, reflections {}, "
      "--vram {}\n",
      options.file.filename().string(), options.width, options.height, gpu.properties.deviceName,
      options.benchFrames, base.samples, base.shadows ? "on" : "off",
      base.reflections && base.material.reflectivity > 0 ? "on" : "off", byteSize(options.vram));
  fmt::print("  ms/frame    mean {:.2f}, median {:.2f}, max {:.2f}\n", mean,
             sorted.empty() ? 0 : sorted[sorted.size() / 2], sorted.empty() ? 0 : sorted.back());
  fmt::print(
      "  rays/s      {:.2f} M ({:.2f} rays a pixel)\n", total > 0 ? rays / total / 1e6 : 0,
      double(rays) / std::max<size_t>(ms.size(), 1) / (double(options.width) * options.height));
  fmt::print("  GPU memory  {} in use, {} at most; pool {} of {}\n", byteSize(s.vramInUse),
             byteSize(s.vramPeak), byteSize(s.poolBytesInUse), byteSize(s.poolBytes));
  fmt::print("  chunks      {} resident at the end, {} at most, of {}\n", s.resident, maxResident,
             asset->reader.chunks().size());
  const size_t half = uploaded.size() / 2;
  const uint64_t upLater = std::accumulate(uploaded.begin() + half, uploaded.end(), uint64_t(0));
  fmt::print(
      "  streamed    {} in all, {:.1f} KiB a frame on average ({:.1f} KiB in the second "
      "half of the path), {} at most in a frame\n",
      byteSize(upTotal), upTotal / 1024.0 / uploaded.size(),
      upLater / 1024.0 / std::max<size_t>(uploaded.size() - half, 1), byteSize(upMax));
  return *gpu.validationErrors > 0 ? 1 : 0;
}

}  // namespace iso::viewer
