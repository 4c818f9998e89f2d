// `iso view SCAN...` in a window (image_view.h): image-space points drawn on the GPU from the
// first batch read on, the points replaced as more arrive (and, when more were read than fit,
// by those of each view the camera rests at), each frame's picture copied to the swapchain.
//
// Mouse and W A S D Q E move the camera as in the tracer's window. Keys: M shading (lit, or
// eye-dome from the depth alone), L layers (1, 2, 3, 6), 1 shadows, + and - shadow samples,
// P screenshot, R reloads the scene file (it also reloads by itself when the file changes), Esc
// quits.
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <optional>

#include "base/image.h"
#include "viewer/image_view.h"
#include "viewer/point_image_gpu.h"
#include "viewer/window_parts.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;
double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

constexpr int kLayerSteps[] = {1, 2, 3, 6};
constexpr double kRest = 0.3;  // seconds the camera rests before its view's points are asked for

bool sameView(const ImageFeed::View& a, const ImageFeed::View& b) {
  return a.camera.eye == b.camera.eye && a.camera.target == b.camera.target &&
         a.camera.up == b.camera.up && a.camera.fovDegrees == b.camera.fovDegrees &&
         a.width == b.width && a.height == b.height;
}

// What keys M, L, 1, + and - changed: kept over the scene file when it is reloaded.
struct ImageKeys {
  std::optional<bool> shadows, eyeDome;
  std::optional<int> layers, shadowSamples;

  void apply(Scene& scene) const {
    if (shadows) scene.shadows = *shadows;
    if (eyeDome) scene.image.eyeDome = *eyeDome;
    if (layers) scene.image.layers = *layers;
    if (shadowSamples) scene.image.shadowSamples = *shadowSamples;
  }
};

void applyImageSwitches(Input& input, Scene& scene, ImageViewOptions& image, ImageKeys& keys) {
  for (const int toggled : input.toggled) {
    if (toggled == 1) keys.shadows = !scene.shadows;
    if (toggled == 7) {
      keys.eyeDome = !(scene.image.eyeDome || image.settings.eyeDome);
      image.settings.eyeDome = false;  // the key decides from now on
    }
    if (toggled == 8) {
      const int* next = std::upper_bound(std::begin(kLayerSteps), std::end(kLayerSteps),
                                         scene.image.layers);
      keys.layers = next == std::end(kLayerSteps) ? kLayerSteps[0] : *next;
    }
    keys.apply(scene);
  }
  input.toggled.clear();
  if (input.samples != 0)
    keys.shadowSamples = std::clamp(std::max(scene.image.shadowSamples, 1) + input.samples, 1,
                                    kMaxImageShadowSamples);
  input.samples = 0;
  keys.apply(scene);
}

// The points being drawn: the feed's latest inputs on the device (none yet: an empty scene).
struct Drawn {
  std::shared_ptr<const ImageInputs> inputs;
  std::unique_ptr<PointImageScene> scene;
  std::unique_ptr<GpuPointImage> renderer;  // draws *scene
};

}  // namespace

int viewImageWindow(const ViewOptions& options, const ImageViewOptions& imageOptions,
                    ImageFeed& feed) {
  const auto opened = Clock::now();
  const std::string title = "iso view " + options.file.filename().string();
  const GlfwWindow glfw(options.width, options.height, title);
  GLFWwindow* window = glfw.window();
  PictureWindowGpu w(window, options);
  Scene scene = options.scene;
  ImageViewOptions image = imageOptions;
  ImageKeys keys;
  // The pipelines are made (compiled, on a CPU device) while the first points are read.
  Drawn drawn;
  drawn.scene = std::make_unique<PointImageScene>(std::vector<ImageObject>{});
  drawn.renderer = std::make_unique<GpuPointImage>(w.gpu, *drawn.scene);
  std::vector<float> drawnOpacity;
  uint64_t version = 0;
  bool cameraMoved = false, final = false;
  auto lastMove = Clock::now();
  std::optional<ImageFeed::View> asked;  // the last view asked for
  std::optional<double> firstPicture;

  Input input;
  listen(window, input);
  std::filesystem::file_time_type sceneTime{};
  if (!options.sceneFile.empty()) sceneTime = std::filesystem::last_write_time(options.sceneFile);
  bool stale = false;
  Mouse mouse;
  glfwGetCursorPos(window, &mouse.x, &mouse.y);
  auto last = Clock::now(), titleTime = last;
  uint32_t frames = 0, titleFrames = 0, screenshots = 0;
  double frameSeconds = 0.0;
  std::vector<uint32_t> lastPicture;
  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    const auto now = Clock::now();
    const double dt = seconds(now - last);
    last = now;
    // New points (a preview, or all of them): on the device in place of the last.
    std::shared_ptr<const ImageInputs> next = feed.since(version);
    if (next || (drawn.inputs && drawnOpacity != scene.image.opacity)) {
      if (!next) next = drawn.inputs;
      auto points = std::make_unique<PointImageScene>(withOpacity(next->objects, scene.image));
      drawn.renderer->setScene(*points);
      drawn.scene = std::move(points);
      drawnOpacity = scene.image.opacity;
      if (!cameraMoved && !options.scene.camera)
        scene.camera = sceneCamera(options.scene, *next, aspectOf(options));
      drawn.inputs = next;
      final = !next->preview;
      // The first of all the points was chosen for the framed view.
      if (final && !asked)
        asked = ImageFeed::View{*scene.camera, w.swapchain.extent.width, w.swapchain.extent.height};
      fmt::print("iso view: {} {} points of {} read{} ({:.2f} s after opening)\n",
                 final ? "drawing" : "drawing a preview of", drawn.scene->size(), next->pointsRead,
                 next->choice.empty() ? "" : ", " + next->choice, seconds(Clock::now() - opened));
      std::fflush(stdout);  // a session watching the output sees it now
    }
    if (!drawn.inputs) {
      glfwWaitEventsTimeout(0.02);  // nothing read yet
      continue;
    }
    if (std::exchange(input.home, false)) {
      scene.camera = sceneCamera(options.scene, *drawn.inputs, aspectOf(w.swapchain));
      cameraMoved = false;
      lastMove = now;
    }
    if (moveCamera(window, *scene.camera, input, mouse, dt, w.swapchain.extent.height)) {
      cameraMoved = true;
      lastMove = now;
    }
    // Points chosen for a view (more were read than fit): ask for the view the camera rests at.
    const ImageFeed::View resting{*scene.camera, w.swapchain.extent.width,
                                  w.swapchain.extent.height};
    if (final && !drawn.inputs->choice.empty() && seconds(now - lastMove) > kRest &&
        (!asked || !sameView(*asked, resting))) {
      feed.want(resting);
      asked = resting;
    }
    applyImageSwitches(input, scene, image, keys);
    reloadScene(options, input, scene, sceneTime, [&](Scene& next) { keys.apply(next); });
    if (!fitToWindow(window, w, stale)) continue;  // minimized
    const ImageInputs& in = *drawn.inputs;
    const auto lights = lightsOf(scene, in, *scene.camera);
    ViewOptions sized = options;
    sized.width = w.swapchain.extent.width;
    sized.height = w.swapchain.extent.height;
    const ImageSettings settings =
        budgeted(settingsOf(scene, image), sized, drawn.scene->size(), lights.size());
    // Previews are drawn at half the size and shown doubled: their sparse points need fewer
    // filling passes, and the first picture comes sooner.
    const uint32_t scale = final ? 1 : 2;
    const uint32_t drawWidth = (sized.width + scale - 1) / scale;
    const uint32_t drawHeight = (sized.height + scale - 1) / scale;
    const auto t0 = Clock::now();
    GpuImageFrame frame = drawn.renderer->render(
        cameraOf(in, *scene.camera, drawWidth, drawHeight), lights, settings);
    frameSeconds += seconds(Clock::now() - t0);
    if (scale > 1) frame.pixels = enlarged(frame.pixels, drawWidth, sized.width, sized.height, scale);
    stale = w.show(frame.pixels);
    lastPicture = std::move(frame.pixels);
    if (!firstPicture) {
      firstPicture = seconds(Clock::now() - opened);
      fmt::print("iso view: first picture {:.2f} s after opening (its frame {:.2f} s)\n",
                 *firstPicture, seconds(Clock::now() - t0));
    }
    ++titleFrames;
    if (final) ++frames;  // --frames counts the frames of all the points
    const bool lastFrame =
        (options.frames > 0 && frames >= options.frames) || glfwWindowShouldClose(window);
    saveScreenshots(input, options, lastFrame, sized.width, sized.height, lastPicture, screenshots);
    const double sinceTitle = seconds(Clock::now() - titleTime);
    if (sinceTitle > 0.5 || lastFrame) {
      const std::string text = fmt::format(
          "{} | {:.1f} ms ({:.0f} fps) | {} points{} | {} | {} layer{} | shadows {} | GPU memory "
          "{:.1f} MiB",
          title, frameSeconds / titleFrames * 1e3, titleFrames / sinceTitle, drawn.scene->size(),
          final ? "" : " (loading)", settings.eyeDome ? "eye-dome" : "lit", settings.layers,
          settings.layers == 1 ? "" : "s",
          !settings.shadows ? std::string("off")
                            : fmt::format("{} sample{}", lights.front().samples,
                                          lights.front().samples == 1 ? "" : "s"),
          double(w.gpu.memoryInUse) / (1 << 20));
      glfwSetWindowTitle(window, text.c_str());
      if (lastFrame) fmt::print("{}\n", text);
      titleTime = Clock::now();
      titleFrames = 0;
      frameSeconds = 0.0;
    }
    if (lastFrame) break;
  }
  vkDeviceWaitIdle(w.gpu.device);
  drawn.renderer.reset();
  if (*w.gpu.validationErrors == 0) return 0;
  fmt::print(stderr, "iso view: {} Vulkan validation errors\n", w.gpu.validationErrors->load());
  return 1;
}

}  // namespace iso::viewer
