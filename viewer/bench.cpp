// `iso view --bench` (view.h; specs/viewer.md, "The benchmark"): a camera orbit rendered as a
// pipelined sequence of frames, timed by the host (the wall time from one frame's completion to
// the next) and by the GPU's timestamps (the dispatch alone), with the first view traced once
// more by the CPU reference tracer, so that GPU and CPU are compared in one run.
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numeric>

#include "base/text.h"
#include "tracer/cpu_tracer.h"
#include "viewer/gpu_view.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// Median, 95th percentile (nearest rank), largest and mean of some values.
struct Spread {
  double median = 0, p95 = 0, max = 0, mean = 0;
  double maxOverMedian() const { return median > 0 ? max / median : 0; }
};

Spread spreadOf(std::vector<double> v) {
  Spread s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  s.median = (v[(n - 1) / 2] + v[n / 2]) / 2;
  s.p95 = v[size_t(std::ceil(0.95 * double(n))) - 1];
  s.max = v.back();
  s.mean = std::accumulate(v.begin(), v.end(), 0.0) / double(n);
  return s;
}

// Rays a second, by kind.
struct RayRates {
  double primary = 0, shadow = 0, secondary = 0, all = 0;
};

RayRates ratesOf(const RayCounts& r, double seconds) {
  if (seconds <= 0) return {};
  return {double(r.primary) / seconds, double(r.shadow) / seconds, double(r.secondary) / seconds,
          double(r.total()) / seconds};
}

// The scene of orbit frame f of n: the camera turned by 2πf/n around its target, about its up.
Scene orbitScene(const Scene& base, uint32_t f, uint32_t n) {
  Scene scene = base;
  const Camera& c = *base.camera;
  scene.camera->eye = c.target + rotated(c.eye - c.target, normalized(c.up), 2 * M_PI * f / n);
  return scene;
}

struct Orbit {
  FrameStats first;  // the first view, rendered frame by frame until it converged or stalled
  uint32_t firstFrames = 0;
  bool firstConverged = false;
  gpu::FrameParams firstParams{};  // with its frame number
  std::vector<FrameStats> frames;  // the other views, pipelined, in order
  std::vector<double> wallMs;      // per frame: from the previous completion to its own
  std::vector<double> idleMs;      // per frame after the first: the GPU idle before it
  double wallSeconds = 0;          // from the first submit to the last completion
  uint32_t maxResident = 0;
  RayCounts rays;  // of `frames`
  double dispatchSeconds = 0, gpuSeconds = 0;
};

// The first view of the orbit, frame by frame as --headless renders, so that it shows what the
// CPU draws with the whole file resident; then the other views with frames in flight. The orbit
// goes on past its last view for the frames in flight less one, untimed, so that every timed
// frame completes while the next ones are queued (a drain would show frames completing at once).
Orbit runOrbit(GpuView& view, const ViewOptions& o) {
  Orbit orbit;
  Renderer& r = view.renderer;
  orbit.firstParams = view.params(orbitScene(view.scene, 0, o.benchFrames));
  do {
    renderFrame(r, orbit.firstParams);
    r.finish();
    ++orbit.firstFrames;
  } while (!r.converged() && !r.stalled() && orbit.firstFrames < o.maxFrames);
  orbit.first = r.stats();
  orbit.firstConverged = r.converged();
  orbit.firstParams.image.w = uint32_t(orbit.first.frame);
  auto previous = Clock::now();
  const auto start = previous;
  const uint64_t lastTimed = orbit.first.frame + o.benchFrames - 1;
  r.onCollected([&](const FrameStats& s) {
    if (s.frame > lastTimed) return;
    if (!orbit.frames.empty() && s.gpuStart > 0)
      orbit.idleMs.push_back(std::max(0.0, s.gpuStart - orbit.frames.back().gpuEnd) * 1e3);
    orbit.frames.push_back(s);
    orbit.wallMs.push_back(seconds(s.completed - previous) * 1e3);
    previous = s.completed;
    orbit.maxResident = std::max(orbit.maxResident, s.resident);
    orbit.rays += s.rays;
    orbit.dispatchSeconds += s.dispatchSeconds;
    orbit.gpuSeconds += s.gpuSeconds;
  });
  for (uint32_t f = 1; f < o.benchFrames + r.framesInFlight() - 1; ++f)
    renderFrame(r, view.params(orbitScene(view.scene, f, o.benchFrames)));
  r.finish();
  r.onCollected({});
  orbit.wallSeconds = seconds(previous - start);
  return orbit;
}

struct CpuRun {
  bool ran = false;
  RayCounts rays;
  double seconds = 0, loadSeconds = 0;  // the median of `runs` renders
  uint32_t runs = 0;
  uint64_t splatPoints = 0, splatBytes = 0;  // CpuPool's
};

// The first view on the CPU reference tracer, with the whole file resident: rendered 3 times at
// least and for half a second at least (20 times at most), the median time.
CpuRun runCpu(const GpuView& view, const gpu::FrameParams& params) {
  CpuRun run;
  const auto t0 = Clock::now();
  CpuPool pool = buildCpuPool(view.asset->reader, {}, view.scene.draw != Draw::Surface);
  pool.pss = view.pss;
  run.loadSeconds = seconds(Clock::now() - t0);
  run.splatPoints = pool.splatPoints;
  run.splatBytes = pool.splatBytes;
  std::vector<double> times;
  double total = 0;
  while (times.size() < 20 && (times.size() < 3 || total < 0.5)) {
    const auto t1 = Clock::now();
    run.rays = renderCpu(pool, params, view.env ? &*view.env : nullptr).rays;
    times.push_back(seconds(Clock::now() - t1));
    total += times.back();
  }
  run.seconds = spreadOf(times).median;
  run.runs = uint32_t(times.size());
  run.ran = true;
  return run;
}

json spreadJson(const Spread& s) {
  return {{"median", s.median},
          {"p95", s.p95},
          {"max", s.max},
          {"mean", s.mean},
          {"max_over_median", s.maxOverMedian()}};
}

json raysJson(const RayCounts& r) {
  return {{"primary", r.primary}, {"shadow", r.shadow}, {"secondary", r.secondary}};
}

json ratesJson(const RayRates& r) {
  return {{"primary", r.primary}, {"shadow", r.shadow}, {"secondary", r.secondary}, {"all", r.all}};
}

// Everything the benchmark measured.
struct BenchNumbers {
  Spread wallMs, gpuMs, idleMs;
  bool timestamps = false;
  RayRates gpuRates, cpuRates;
  double raysPerPixel = 0, fps = 0;
  std::vector<double> uploaded;  // bytes per orbit frame
};

BenchNumbers numbersOf(const GpuView& view, const ViewOptions& o, const Orbit& orbit,
                       const CpuRun& cpu) {
  BenchNumbers n;
  n.wallMs = spreadOf(orbit.wallMs);
  std::vector<double> gpuMs;
  for (const FrameStats& s : orbit.frames) gpuMs.push_back(s.dispatchSeconds * 1e3);
  n.timestamps = view.renderer.hasTimestamps() && orbit.dispatchSeconds > 0;
  if (n.timestamps) n.gpuMs = spreadOf(gpuMs);
  if (n.timestamps) n.idleMs = spreadOf(orbit.idleMs);
  n.gpuRates = ratesOf(orbit.rays, n.timestamps ? orbit.dispatchSeconds : orbit.wallSeconds);
  if (cpu.ran) n.cpuRates = ratesOf(cpu.rays, cpu.seconds);
  const double frames = double(std::max<size_t>(orbit.frames.size(), 1));
  n.raysPerPixel = double(orbit.rays.total()) / frames / (double(o.width) * o.height);
  n.fps = orbit.wallSeconds > 0 ? double(orbit.frames.size()) / orbit.wallSeconds : 0;
  for (const FrameStats& s : orbit.frames) n.uploaded.push_back(double(s.uploadedBytes));
  return n;
}

json benchJson(const GpuView& view, const ViewOptions& o, const Orbit& orbit, const CpuRun& cpu,
               const BenchNumbers& n) {
  const FrameStats& last = view.renderer.stats();
  const Spread up = spreadOf(n.uploaded);
  json j = {{"file", o.file.string()},
            {"device", view.gpu.properties.deviceName},
            {"width", o.width},
            {"height", o.height},
            {"frames", o.benchFrames},
            {"frames_in_flight", view.renderer.framesInFlight()},
            {"vram", o.vram},
            {"two_passes", last.twoPasses},
            {"mirror_bounces", last.mirrorBounces},
            {"first_view",
             {{"frames", orbit.firstFrames},
              {"converged", orbit.firstConverged},
              {"streamed_bytes", orbit.first.streamedBytes},
              {"rays", raysJson(orbit.first.rays)}}},
            {"wall_ms", spreadJson(n.wallMs)},
            {"fps", n.fps},
            {"gpu_ms", n.timestamps ? spreadJson(n.gpuMs) : json()},
            {"gpu_idle_ms", n.timestamps ? spreadJson(n.idleMs) : json()},
            {"rays_per_second", ratesJson(n.gpuRates)},
            {"rays_per_second_from", n.timestamps ? "timestamps" : "wall"},
            {"rays_per_pixel", n.raysPerPixel},
            {"gpu_memory",
             {{"in_use", last.vramInUse},
              {"peak", last.vramPeak},
              {"pool", last.poolBytes},
              {"pool_in_use", last.poolBytesInUse}}},
            {"chunks",
             {{"resident", last.resident},
              {"max_resident", orbit.maxResident},
              {"total", view.asset->reader.chunks().size()}}},
            {"streamed_per_frame", spreadJson(up)}};
  json frames = json::array();
  for (size_t i = 0; i < orbit.frames.size(); ++i) {
    const FrameStats& s = orbit.frames[i];
    frames.push_back(
        {{"wall_ms", orbit.wallMs[i]},
         {"dispatch_ms", s.dispatchSeconds * 1e3},
         {"gpu_ms", s.gpuSeconds * 1e3},
         {"gpu_idle_ms", i > 0 && i <= orbit.idleMs.size() ? json(orbit.idleMs[i - 1]) : json()},
         {"rays", raysJson(s.rays)},
         {"uploaded_bytes", s.uploadedBytes},
         {"evicted", s.evicted},
         {"resident", s.resident}});
  }
  j["orbit_frames"] = frames;
  if (cpu.ran)
    j["cpu"] = {{"seconds", cpu.seconds},
                {"renders", cpu.runs},
                {"load_seconds", cpu.loadSeconds},
                {"splat_points", cpu.splatPoints},
                {"splat_blob_bytes", cpu.splatBytes},
                {"rays", raysJson(cpu.rays)},
                {"rays_per_second", ratesJson(n.cpuRates)},
                {"gpu_over_cpu",
                 {{"primary", n.gpuRates.primary / std::max(n.cpuRates.primary, 1e-9)},
                  {"all", n.gpuRates.all / std::max(n.cpuRates.all, 1e-9)}}}};
  return j;
}

std::string ratesText(const RayRates& r) {
  return fmt::format("all {:.2f} M, primary {:.2f} M, shadow {:.2f} M, secondary {:.2f} M",
                     r.all / 1e6, r.primary / 1e6, r.shadow / 1e6, r.secondary / 1e6);
}

std::string raysText(const RayCounts& r) {
  return fmt::format("primary {}, shadow {}, secondary {}", r.primary, r.shadow, r.secondary);
}

void printTimes(const Orbit& orbit, const BenchNumbers& n) {
  fmt::print(
      "  ms/frame    median {:.2f}, p95 {:.2f}, max {:.2f}, max/median {:.2f}, mean {:.2f} (wall "
      "time between frames, pipelined); {:.2f} frames/s\n",
      n.wallMs.median, n.wallMs.p95, n.wallMs.max, n.wallMs.maxOverMedian(), n.wallMs.mean, n.fps);
  if (n.timestamps)
    fmt::print(
        "  GPU ms      median {:.2f}, p95 {:.2f}, max {:.2f}, max/median {:.2f} (the dispatch, "
        "from timestamps); {:.2f} with the uploads, on average\n",
        n.gpuMs.median, n.gpuMs.p95, n.gpuMs.max, n.gpuMs.maxOverMedian(),
        orbit.gpuSeconds * 1e3 / double(std::max<size_t>(orbit.frames.size(), 1)));
  if (n.timestamps)
    fmt::print(
        "  GPU idle    median {:.2f}, max {:.2f} ms between one frame's end and the next one's "
        "start (timestamps; the host did not keep the queue fed when large)\n",
        n.idleMs.median, n.idleMs.max);
  else
    fmt::print("  GPU ms      no timestamps on this queue\n");
  fmt::print("  rays/s      {} ({}; {:.2f} rays a pixel)\n", ratesText(n.gpuRates),
             n.timestamps ? "GPU timestamps, the dispatch alone" : "wall time", n.raysPerPixel);
}

void printCpu(const Orbit& orbit, const CpuRun& cpu, const BenchNumbers& n) {
  fmt::print("  first view  {} frame{} to {}; rays {}\n", orbit.firstFrames,
             orbit.firstFrames == 1 ? "" : "s",
             orbit.firstConverged ? "converge" : "stop (not converged)",
             raysText(orbit.first.rays));
  if (!cpu.ran) return;
  fmt::print(
      "  CPU         the first view in {:.3f} s (the median of {} renders; chunks decoded in "
      "{:.2f} s); rays {}\n",
      cpu.seconds, cpu.runs, cpu.loadSeconds, raysText(cpu.rays));
  fmt::print("  CPU rays/s  {}\n", ratesText(n.cpuRates));
  if (cpu.splatPoints > 0)
    fmt::print("  splats      {} points in splat blobs (subsamples too), {:.2f} bytes a point\n",
               cpu.splatPoints, double(cpu.splatBytes) / double(cpu.splatPoints));
  fmt::print("  GPU/CPU     primary rays/s {:.3f}, all rays/s {:.3f}\n",
             n.gpuRates.primary / std::max(n.cpuRates.primary, 1e-9),
             n.gpuRates.all / std::max(n.cpuRates.all, 1e-9));
}

void printBench(const GpuView& view, const ViewOptions& o, const Orbit& orbit, const CpuRun& cpu,
                const BenchNumbers& n) {
  const Scene& base = view.scene;
  const FrameStats& s = view.renderer.stats();
  fmt::print(
      "bench {}: {}x{} on {}, {} frames orbiting, {} in flight, samples {}, shadows {}, "
      "reflections {}, --vram {}, {}\n",
      o.file.filename().string(), o.width, o.height, view.gpu.properties.deviceName, o.benchFrames,
      view.renderer.framesInFlight(), base.samples, base.shadows ? "on" : "off",
      base.reflections && base.material.reflectivity > 0 ? "on" : "off", byteSize(o.vram),
      !s.twoPasses ? std::string("one kernel")
      : s.mirrorBounces == 0
          ? std::string("two passes (camera rays, then shading)")
          : fmt::format("a wavefront (camera rays, shading, then {} bounce{} of mirror rays and "
                        "their shading)",
                        s.mirrorBounces, s.mirrorBounces == 1 ? "" : "s"));
  printTimes(orbit, n);
  printCpu(orbit, cpu, n);
  fmt::print("  GPU memory  {} in use, {} at most; pool {} of {}\n", byteSize(s.vramInUse),
             byteSize(s.vramPeak), byteSize(s.poolBytesInUse), byteSize(s.poolBytes));
  fmt::print("  chunks      {} resident at the end, {} at most, of {}\n", s.resident,
             orbit.maxResident, view.asset->reader.chunks().size());
  const Spread up = spreadOf(n.uploaded);
  const size_t half = n.uploaded.size() / 2;
  const double later = std::accumulate(n.uploaded.begin() + half, n.uploaded.end(), 0.0) /
                       double(std::max<size_t>(n.uploaded.size() - half, 1));
  fmt::print(
      "  streamed    {} for the first view; then {:.1f} KiB a frame on average ({:.1f} KiB in "
      "the second half of the path), {} at most in a frame\n",
      byteSize(orbit.first.streamedBytes), up.mean / 1024, later / 1024,
      byteSize(uint64_t(up.max)));
}

}  // namespace

int viewBench(const ViewOptions& options) {
  GpuView view(options, options.framesInFlight);
  const Orbit orbit = runOrbit(view, options);
  const CpuRun cpu = options.cpuCompare ? runCpu(view, orbit.firstParams) : CpuRun{};
  const BenchNumbers numbers = numbersOf(view, options, orbit, cpu);
  if (options.benchJson)
    fmt::print("{}\n", benchJson(view, options, orbit, cpu, numbers).dump(2));
  else
    printBench(view, options, orbit, cpu, numbers);
  if (*view.gpu.validationErrors > 0) {
    fmt::print(stderr, "iso view: {} Vulkan validation errors\n",
               view.gpu.validationErrors->load());
    return 1;
  }
  return 0;
}

}  // namespace iso::viewer
