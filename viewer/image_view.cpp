// `iso view --draw image` (image_view.h).
#include "viewer/image_view.h"

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "base/image.h"
#include "viewer/point_image_gpu.h"
#include "viewer/vulkan.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;
double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

static glm::vec3 local(const ImageInputs& in, const Vec3d& world) {
  return glm::vec3(world - in.origin);
}

// The scene's camera (framed on the points when it has none) in the points' frame.
ImageCamera cameraOf(const ImageInputs& in, const Camera& c, uint32_t width, uint32_t height) {
  ImageCamera camera;
  camera.eye = local(in, c.eye);
  camera.target = local(in, c.target);
  camera.up = glm::vec3(c.up);
  camera.fovDegrees = float(c.fovDegrees);
  camera.width = int(width);
  camera.height = int(height);
  return camera;
}

Camera sceneCamera(const Scene& s, const ImageInputs& in, double aspect) {
  if (s.camera) {
    Camera c = *s.camera;
    if (s.fovDegrees) c.fovDegrees = *s.fovDegrees;
    return c;
  }
  // The inputs' framing, or their points as cells of their spacing: about kFramingPoints of
  // them, each as wide as the points it stands for.
  std::vector<SurfaceCell> cells = in.framing;
  if (cells.empty()) {
    size_t points = 0;
    for (const ImageObject& o : in.objects) points += o.positions.size();
    const size_t stride = std::max<size_t>(1, points / kFramingPoints);
    for (const ImageObject& o : in.objects)
      for (size_t i = 0; i < o.positions.size(); i += stride)
        cells.push_back({in.origin + Vec3d(o.positions[i]), o.spacing * std::sqrt(double(stride))});
  }
  return defaultCamera(cells, s.up.value_or(in.up), s.fovDegrees.value_or(40.0), aspect);
}

std::vector<ImageLight> lightsOf(const Scene& scene, const ImageInputs& in,
                                 const Camera& camera) {
  const int shadowSamples = scene.image.shadowSamples;
  std::vector<LightSpec> specs = scene.lights;
  if (specs.empty()) specs.push_back(defaultLight(camera, in.bounds));
  std::vector<ImageLight> lights;
  for (const LightSpec& s : specs) {
    ImageLight l;
    l.position = local(in, s.position);
    l.color = glm::vec3(s.color[0], s.color[1], s.color[2]) * s.intensity;
    if (s.area) {
      l.u = glm::vec3(s.u);
      l.v = glm::vec3(s.v);
      l.samples = shadowSamples > 0 ? shadowSamples : s.samples;
    } else if (shadowSamples > 1) {
      // Soft shadows asked for a point light: a square light a twentieth of the scene wide,
      // across the direction to the scene.
      const glm::vec3 toScene = glm::normalize(local(in, 0.5 * (in.bounds.lo + in.bounds.hi)) -
                                               l.position);
      glm::vec3 a = glm::cross(toScene, glm::vec3(0, 0, 1));
      if (glm::dot(a, a) < 1e-6f) a = glm::cross(toScene, glm::vec3(1, 0, 0));
      a = glm::normalize(a);
      const float size = 0.05f * float(glm::length(in.bounds.hi - in.bounds.lo));
      l.u = size * a;
      l.v = size * glm::normalize(glm::cross(toScene, a));
      l.samples = shadowSamples;
    }
    lights.push_back(l);
  }
  return lights;
}

ImageSettings settingsOf(const Scene& scene, const ImageViewOptions& image) {
  ImageSettings s = image.settings;
  s.layers = scene.image.layers;
  s.layerGap = float(scene.image.layerGap);
  s.eyeDome = s.eyeDome || scene.image.eyeDome;
  s.shadows = s.shadows && scene.shadows;
  s.ambient = glm::vec3(scene.ambient[0], scene.ambient[1], scene.ambient[2]);
  s.diffuse = scene.material.diffuse;
  s.specular = scene.material.specular;
  s.shininess = scene.material.shininess;
  return s;
}

std::vector<ImageObject> withOpacity(const std::vector<ImageObject>& objects,
                                     const ImageScene& scene) {
  const std::vector<float>& a = scene.opacity;
  if (!a.empty() && a.size() != 1 && a.size() != objects.size())
    throw UsageError(fmt::format("opacity: one number, or one for each of the {} inputs (got {})",
                                 objects.size(), a.size()));
  std::vector<ImageObject> out = objects;
  for (size_t i = 0; i < out.size() && !a.empty(); ++i) out[i].opacity = a[a.size() == 1 ? 0 : i];
  return out;
}

// The budget's largest light image for these points (imageBudget).
ImageSettings budgeted(ImageSettings s, const ViewOptions& o, size_t points, size_t lights) {
  s.maxShadowResolution = imageBudget(o.vram, points, o.width, o.height, lights).shadowResolution;
  return s;
}

namespace {

// The picture of a frame's linear colors (the CPU reference), as the GPU writes it.
std::vector<uint32_t> pixelsOf(const ImageResult& r) {
  std::vector<uint32_t> pixels(r.color.size());
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = imagePixelWord(r.color[i]);
  return pixels;
}

void printInputs(const ImageInputs& in, size_t points) {
  fmt::print("{} point{} from {} file{}{}{}, read and prepared in {:.2f} s\n", points,
             points == 1 ? "" : "s", in.names.size(), in.names.size() == 1 ? "" : "s",
             in.choice.empty() ? std::string() : " (" + in.choice + ")",
             in.normalsEstimated ? " (normals estimated)" : "", in.loadSeconds);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int viewImageHeadless(const ViewOptions& o, const ImageViewOptions& image,
                      const ImageInputs& in) {
  Gpu gpu = gpuFor(o);
  const PointImageScene scene(withOpacity(in.objects, o.scene.image));
  const Camera camera = sceneCamera(o.scene, in, aspectOf(o));
  const auto lights = lightsOf(o.scene, in, camera);
  GpuPointImage renderer(gpu, scene);
  if (image.fillRoundsPerSubmit > 0) renderer.setRoundsPerSubmit(image.fillRoundsPerSubmit);
  const auto t0 = Clock::now();
  const GpuImageFrame frame =
      renderer.render(cameraOf(in, camera, o.width, o.height), lights,
                      budgeted(settingsOf(o.scene, image), o, scene.size(), lights.size()));
  const double wall = seconds(Clock::now() - t0);
  writeRgba8Image(o.out, o.width, o.height, frame.pixels);
  printInputs(in, scene.size());
  fmt::print("{}: {}x{} image-space points on {}, {} layer{}, {:.3f} s ({:.3f} s GPU), GPU memory "
             "{:.1f} MiB\n",
             o.out.string(), o.width, o.height, gpu.properties.deviceName, frame.stats.layers,
             frame.stats.layers == 1 ? "" : "s", wall, frame.gpuSeconds,
             double(gpu.memoryPeak) / (1 << 20));
  if (o.validation && gpu.validationErrors->load() > 0)
    throw std::runtime_error("Vulkan validation errors");
  return 0;
}

int viewImageCpu(const ViewOptions& o, const ImageViewOptions& image, const ImageInputs& in) {
  PointImageRenderer renderer(withOpacity(in.objects, o.scene.image));
  const Camera camera = sceneCamera(o.scene, in, aspectOf(o));
  const auto lights = lightsOf(o.scene, in, camera);
  const auto t0 = Clock::now();
  const ImageResult r = renderer.render(
      cameraOf(in, camera, o.width, o.height), lights,
      budgeted(settingsOf(o.scene, image), o, renderer.scene().size(), lights.size()));
  const double render = seconds(Clock::now() - t0);
  writeRgba8Image(o.out, o.width, o.height, pixelsOf(r));
  printInputs(in, renderer.scene().size());
  fmt::print("{}: {}x{} image-space points on the CPU reference, {} layer{}, {:.2f} s\n",
             o.out.string(), o.width, o.height, r.stats.layers, r.stats.layers == 1 ? "" : "s",
             render);
  return 0;
}

int viewImageBench(const ViewOptions& o, const ImageViewOptions& image, const ImageInputs& in) {
  Gpu gpu = gpuFor(o);
  const std::vector<ImageObject> objects = withOpacity(in.objects, o.scene.image);
  const PointImageScene scene(objects);
  const Camera start = sceneCamera(o.scene, in, aspectOf(o));
  const auto lights = lightsOf(o.scene, in, start);
  ImageSettings settings =
      budgeted(settingsOf(o.scene, image), o, scene.size(), lights.size());
  // Every frame computes its shadow textures, as the paper's timings do.
  settings.reuseShadows = false;
  const auto t0 = Clock::now();
  GpuPointImage renderer(gpu, scene);
  if (image.fillRoundsPerSubmit > 0) renderer.setRoundsPerSubmit(image.fillRoundsPerSubmit);
  const double upload = seconds(Clock::now() - t0);
  std::vector<double> wall, device;
  std::array<double, size_t(ImageStep::Count)> steps{};  // ms summed over the timed frames
  uint64_t projected = 0;
  const uint32_t frames = std::max(o.benchFrames, 2u);
  GpuImageFrame first;
  for (uint32_t f = 0; f < frames; ++f) {
    Camera c = start;
    const Vec3d axis = normalized(c.up);
    c.eye = c.target + rotated(c.eye - c.target, axis, 2.0 * M_PI * f / frames);
    const auto t = Clock::now();
    GpuImageFrame frame = renderer.render(cameraOf(in, c, o.width, o.height), lights, settings);
    if (f == 0) {
      first = std::move(frame);
      continue;  // the first frame compiles and warms: not timed
    }
    wall.push_back(seconds(Clock::now() - t) * 1e3);
    device.push_back(frame.gpuSeconds * 1e3);
    for (size_t k = 0; k < steps.size(); ++k) steps[k] += frame.stepSeconds[k] * 1e3;
    projected = frame.stats.projected;
  }
  // The first view on the CPU reference.
  PointImageRenderer cpu(objects);
  const auto t1 = Clock::now();
  cpu.render(cameraOf(in, start, o.width, o.height), lights, settings);
  const double cpuSeconds = seconds(Clock::now() - t1);
  const double ms = median(wall), gpuMs = median(device);
  for (double& step : steps) step /= double(std::max<size_t>(wall.size(), 1));
  nlohmann::json stepsJson = nlohmann::json::object();
  std::string stepsText;
  for (size_t k = 0; k < steps.size(); ++k) {
    stepsJson[kImageStepNames[k]] = steps[k];
    if (steps[k] >= 0.005) stepsText += fmt::format(" {} {:.2f},", kImageStepNames[k], steps[k]);
  }
  if (!stepsText.empty()) stepsText.pop_back();
  const double fps = 1e3 / std::max(ms, 1e-9);
  const double pointsPerSecond = double(projected) / std::max(gpuMs > 0 ? gpuMs : ms, 1e-9) * 1e3;
  const int samples = lights.empty() || !settings.shadows ? 0 : lights.front().area() ? lights.front().samples : 1;
  if (o.benchJson) {
    nlohmann::json j = {{"files", in.names},
                        {"points", scene.size()},
                        {"device", gpu.properties.deviceName},
                        {"width", o.width},
                        {"height", o.height},
                        {"layers", settings.layers},
                        {"shadow_samples", samples},
                        {"frames", frames - 1},
                        {"ms_per_frame", ms},
                        {"gpu_ms_per_frame", gpuMs},
                        {"frames_per_second", fps},
                        {"points_projected_per_second", pointsPerSecond},
                        {"gpu_memory_bytes", gpu.memoryPeak},
                        {"gpu_ms_per_step", stepsJson},
                        {"load_seconds", in.loadSeconds},
                        {"upload_seconds", upload},
                        {"cpu_seconds", cpuSeconds},
                        {"fill_passes", {{"background", first.stats.backgroundPasses},
                                         {"occluded", first.stats.occludedPasses}}}};
    fmt::print("{}\n", j.dump(2));
    return 0;
  }
  printInputs(in, scene.size());
  fmt::print(
      "bench image: {}x{} on {}, {} point{}, {} layer{}, shadows {}, {} frames orbiting\n"
      "  ms/frame    median {:.2f} ({:.1f} frames/s), GPU {:.2f} ms (timestamps)\n"
      "  GPU steps   ms a frame:{}\n"
      "  points      {:.1f} M projected a second (eye and light passes)\n"
      "  GPU memory  {:.1f} MiB; points uploaded in {:.2f} s\n"
      "  CPU         the first view in {:.2f} s on the CPU reference ({:.1f} times the GPU's "
      "frame)\n",
      o.width, o.height, gpu.properties.deviceName, scene.size(), scene.size() == 1 ? "" : "s",
      settings.layers, settings.layers == 1 ? "" : "s",
      samples == 0 ? std::string("off") : fmt::format("{} sample{}", samples, samples == 1 ? "" : "s"),
      frames - 1, ms, fps, gpuMs, stepsText, pointsPerSecond / 1e6, double(gpu.memoryPeak) / (1 << 20),
      upload, cpuSeconds, cpuSeconds * 1e3 / std::max(ms, 1e-9));
  return 0;
}

void ImageFeed::publish(ImageInputs&& inputs) {
  auto next = std::make_shared<const ImageInputs>(std::move(inputs));
  const std::lock_guard lock(mutex_);
  latest_ = std::move(next);
  ++version_;
}

void ImageFeed::fail(std::exception_ptr error) {
  const std::lock_guard lock(mutex_);
  error_ = error;
}

void ImageFeed::want(const View& view) {
  {
    const std::lock_guard lock(mutex_);
    wanted_ = view;
  }
  viewChanged_.notify_one();
}

std::optional<ImageFeed::View> ImageFeed::wanted(std::chrono::milliseconds wait) {
  std::unique_lock lock(mutex_);
  viewChanged_.wait_for(lock, wait, [&] { return wanted_.has_value(); });
  std::optional<View> view = std::move(wanted_);
  wanted_.reset();
  return view;
}

std::shared_ptr<const ImageInputs> ImageFeed::since(uint64_t& version) const {
  const std::lock_guard lock(mutex_);
  if (error_) std::rethrow_exception(error_);
  if (version == version_) return nullptr;
  version = version_;
  return latest_;
}

}  // namespace iso::viewer
