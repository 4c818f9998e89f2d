// `iso view FILE --draw pss` (image_view.h): the points as a point set surface, ray traced on the
// CPU reference (tracer/pss.h) or the GPU (viewer/pss_gpu.h).
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/geometric.hpp>

#include "base/image.h"
#include "viewer/image_view.h"
#include "tracer/pss.h"
#include "viewer/pss_gpu.h"
#include "viewer/pss_view.h"
#include "viewer/view.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;
double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// The scene's transfer function, or a ramp over the values' range: from dark blue and clear to
// light yellow absorbing 4 over the volume's diagonal.
std::vector<PssTransferPoint> volumeTransfer(const VolumeScene& scene, const PssVolume& volume,
                                            double scale) {
  std::vector<PssTransferPoint> out;
  // (Extinction per unit length: per world unit in the scene file.)
  for (const auto& p : scene.transfer)
    out.push_back({p[0], glm::vec3(p[1], p[2], p[3]), float(p[4] * scale)});
  if (!out.empty() || volume.size() == 0) return out;
  float lo = volume.points()[0].w, hi = lo;
  for (const glm::vec4& p : volume.points()) {
    lo = std::min(lo, p.w);
    hi = std::max(hi, p.w);
  }
  const float diagonal = glm::length(glm::vec3(volume.dims()) * volume.side());
  out.push_back({lo, glm::vec3(0.05f, 0.1f, 0.6f), 0.0f});
  out.push_back({std::max(hi, lo + 1e-6f), glm::vec3(1.0f, 0.85f, 0.3f), 4.0f / diagonal});
  return out;
}

}  // namespace

PssScene pssScene(const ImageInputs& in, const PssViewOptions& pss, const Scene& scene) {
  return pssScene(in, pss, scene, in.origin, 1.0);
}

PssScene pssScene(const ImageInputs& in, const PssViewOptions& pss, const Scene& scene,
                  const glm::dvec3& base, double scale) {
  const auto t0 = Clock::now();
  std::vector<glm::vec3> positions, normals;
  std::vector<float> h;
  PssScene s;
  bool anyColors = false;
  for (const ImageObject& object : in.objects) anyColors |= !object.colors.empty();
  const glm::dvec3 shift = in.origin - base;
  for (const ImageObject& object : in.objects)
    for (size_t i = 0; i < object.positions.size(); ++i) {
      positions.push_back(glm::vec3((glm::dvec3(object.positions[i]) + shift) / scale));
      normals.push_back(object.normals.empty() ? glm::vec3(0.0f) : object.normals[i]);
      h.push_back(float(kPssSpacings *
                        (object.spacings.empty() ? object.spacing : object.spacings[i]) / scale));
      if (anyColors) s.colors.push_back(object.colors.empty() ? object.color : object.colors[i]);
    }
  s.surface = std::make_unique<PssSurface>(std::move(positions), std::move(normals), std::move(h));
  if (!pss.volumePositions.empty()) {
    std::vector<glm::vec3> local;
    for (const glm::dvec3& p : pss.volumePositions) local.push_back(glm::vec3((p - base) / scale));
    s.volume = std::make_unique<PssVolume>(local, pss.volumeValues,
                                           float(scene.volume.smoothing / scale),
                                           float(scene.volume.step / scale));
    s.transfer = volumeTransfer(scene.volume, *s.volume, scale);
  }
  s.fitSeconds = seconds(Clock::now() - t0);
  return s;
}

// The picture's camera, lights and material from the scene, in the points' frame.
PssRender pssRender(const ViewOptions& o, const PssViewOptions& pss, const ImageInputs& in,
                    const PssScene& scene, const Camera& camera) {
  const Scene& s = o.scene;
  PssRender r;
  r.eye = glm::vec3(camera.eye - in.origin);
  r.target = glm::vec3(camera.target - in.origin);
  r.up = glm::vec3(camera.up);
  r.fovDegrees = float(camera.fovDegrees);
  r.width = int(o.width);
  r.height = int(o.height);
  std::vector<LightSpec> lights = s.lights;
  if (lights.empty()) lights.push_back(defaultLight(camera, in.bounds));
  for (const LightSpec& l : lights)
    r.lights.push_back({glm::vec3(l.position - in.origin), l.intensity});
  r.shadows = s.shadows;
  r.material = glm::vec4(s.material.diffuse, s.material.specular, s.material.shininess,
                         s.refractions ? s.material.transparency : 0.0f);
  r.reflectivity = s.reflections ? s.material.reflectivity : 0.0f;
  r.iors = pss.iors;
  r.ambient = s.ambient[1];
  r.color = glm::vec3(s.material.color[0], s.material.color[1], s.material.color[2]);
  r.exact = pss.exact;
  r.volume = scene.volume.get();
  r.transfer = scene.transfer;
  return r;
}

void printScene(const ImageInputs& in, const PssScene& s) {
  fmt::print("{} points from {} file{}{}, a point set surface fitted in {:.2f} s\n",
             s.surface->size(), in.names.size(), in.names.size() == 1 ? "" : "s",
             in.normalsEstimated ? " (normals estimated)" : "", s.fitSeconds);
  if (s.volume)
    fmt::print("a volume of {} points inside it: smoothing {:.4g}, step {:.4g}, a transfer "
               "function of {} points\n",
               s.volume->size(), s.volume->smoothing(), s.volume->step(), s.transfer.size());
}

const char* modeName(const PssViewOptions& pss) { return pss.exact ? "exact" : "fast"; }

int viewPssCpu(const ViewOptions& o, const PssViewOptions& pss, const ImageInputs& in) {
  const PssScene s = pssScene(in, pss, o.scene);
  const PssRender r = pssRender(o, pss, in, s, sceneCamera(o.scene, in, aspectOf(o)));
  const auto t0 = Clock::now();
  const std::vector<glm::vec3> linear = renderPss(*s.surface, s.colors, r);
  const double render = seconds(Clock::now() - t0);
  std::vector<uint32_t> pixels(linear.size());
  for (size_t i = 0; i < linear.size(); ++i) pixels[i] = imagePixelWord(linear[i]);
  writeRgba8Image(o.out, o.width, o.height, pixels);
  printScene(in, s);
  fmt::print("{}: {}x{} point set surface ({} mode) on the CPU reference, {:.2f} s ({:.2f} M "
             "camera rays/s)\n",
             o.out.string(), o.width, o.height, modeName(pss), render,
             double(o.width) * o.height / render * 1e-6);
  return 0;
}

int viewPssHeadless(const ViewOptions& o, const PssViewOptions& pss, const ImageInputs& in) {
  Gpu gpu = gpuFor(o);
  const PssScene s = pssScene(in, pss, o.scene);
  GpuPss renderer(gpu, *s.surface, s.colors);
  double gpuSeconds = 0.0;
  const std::vector<uint32_t> pixels =
      renderer.render(pssRender(o, pss, in, s, sceneCamera(o.scene, in, aspectOf(o))), &gpuSeconds);
  writeRgba8Image(o.out, o.width, o.height, pixels);
  printScene(in, s);
  fmt::print("{}: {}x{} point set surface ({} mode) on {}, {:.3f} s GPU, GPU memory {:.1f} MiB\n",
             o.out.string(), o.width, o.height, modeName(pss), gpu.properties.deviceName,
             gpuSeconds, double(renderer.memoryBytes()) / (1 << 20));
  return 0;
}

int viewPssBench(const ViewOptions& o, const PssViewOptions& pss, const ImageInputs& in) {
  Gpu gpu = gpuFor(o);
  const PssScene s = pssScene(in, pss, o.scene);
  GpuPss renderer(gpu, *s.surface, s.colors);
  const Camera start = sceneCamera(o.scene, in, aspectOf(o));
  const uint32_t frames = std::max(o.benchFrames, 2u);
  std::vector<double> wall, device;
  for (uint32_t f = 0; f < frames; ++f) {
    Camera c = start;
    c.eye = c.target + rotated(c.eye - c.target, normalized(c.up), 2.0 * M_PI * f / frames);
    const auto t = Clock::now();
    double g = 0.0;
    renderer.render(pssRender(o, pss, in, s, c), &g);
    if (f == 0) continue;  // the first frame pays for the pipeline's first use
    wall.push_back(seconds(Clock::now() - t));
    device.push_back(g);
  }
  std::sort(wall.begin(), wall.end());
  std::sort(device.begin(), device.end());
  const double median = wall[wall.size() / 2], gpuMedian = device[device.size() / 2];
  // The CPU reference on the first view.
  const auto t0 = Clock::now();
  renderPss(*s.surface, s.colors, pssRender(o, pss, in, s, start));
  const double cpu = seconds(Clock::now() - t0);
  printScene(in, s);
  fmt::print("bench pss: {}x{} on {}, {} mode, {} points, {} frames orbiting\n", o.width,
             o.height, gpu.properties.deviceName, modeName(pss), s.surface->size(), wall.size());
  fmt::print("  ms/frame    median {:.2f} ({:.1f} frames/s), GPU {:.2f} ms (timestamps)\n",
             median * 1e3, 1.0 / median, gpuMedian * 1e3);
  fmt::print("  rays        {:.2f} M camera rays/s on the GPU, {:.2f} M on the CPU reference\n",
             double(o.width) * o.height / median * 1e-6, double(o.width) * o.height / cpu * 1e-6);
  fmt::print("  GPU memory  {:.1f} MiB\n", double(renderer.memoryBytes()) / (1 << 20));
  fmt::print("  CPU         the first view in {:.2f} s on the CPU reference ({:.1f} times the "
             "GPU's frame)\n",
             cpu, cpu / median);
  return 0;
}

std::shared_ptr<const PssObject> pssObject(const ImageInputs& in, const PssViewOptions& pss,
                                           const Scene& scene, const Frame& frame) {
  PssScene s = pssScene(in, pss, scene, glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]),
                        frame.size);
  printScene(in, s);
  auto object = std::make_shared<PssObject>();
  object->surface = std::move(s.surface);
  object->colors = std::move(s.colors);
  object->volume = std::move(s.volume);
  object->transfer = std::move(s.transfer);
  object->exact = pss.exact;
  return object;
}

}  // namespace iso::viewer
