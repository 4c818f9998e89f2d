// `iso view FILE --draw pss` in a window (image_view.h): the point set surface ray traced on the
// GPU (pss_gpu.h) and shown. A picture is traced only when something changed (with --frames,
// every frame): while the camera moves at a reduced size (enlarged to the window; the size chosen
// from the last frames' rate so that one takes about 50 ms), then at the window's size once it
// has rested 0.3 s.
//
// Mouse and W A S D Q E move the camera as in the tracer's window. Keys: 1 shadows,
// 2 reflections, 3 refractions (the scene's reflectivity and transparency), X fast or exact mode,
// P screenshot, R reloads the scene file (it also reloads by itself when the file changes),
// Esc quits.
#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "base/image.h"
#include "viewer/image_view.h"
#include "viewer/pss_gpu.h"
#include "viewer/pss_view.h"
#include "viewer/window_parts.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;
double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

constexpr double kRest = 0.3;          // seconds the camera rests before the full picture
constexpr double kMovingFrame = 0.05;  // seconds a frame may take while the camera moves
constexpr uint32_t kMaxScale = 16;

}  // namespace

int viewPssWindow(const ViewOptions& options, const PssViewOptions& pssOptions,
                  const ImageInputs& in) {
  const auto opened = Clock::now();
  const std::string title = "iso view " + options.file.filename().string();
  const GlfwWindow glfw(options.width, options.height, title);
  GLFWwindow* window = glfw.window();
  PictureWindowGpu w(window, options);
  PssViewOptions pss = pssOptions;
  ViewOptions o = options;
  const PssScene scene = pssScene(in, pss, o.scene);
  printScene(in, scene);
  GpuPss renderer(w.gpu, *scene.surface, scene.colors);
  Camera camera = sceneCamera(o.scene, in, aspectOf(o));

  Input input;
  listen(window, input);
  std::filesystem::file_time_type sceneTime{};
  if (!o.sceneFile.empty()) sceneTime = std::filesystem::last_write_time(o.sceneFile);
  Mouse mouse;
  glfwGetCursorPos(window, &mouse.x, &mouse.y);
  auto last = Clock::now(), lastMove = last - std::chrono::seconds(1), titleTime = last;
  bool stale = false, changed = true, ended = false;
  uint32_t drawnScale = 0;  // the scale of the picture shown (0: none yet)
  uint32_t scale = 4, frames = 0, screenshots = 0;
  double pixelsPerSecond = 0.0;  // of the last frames, for the moving scale
  double frameSeconds = 0.0;
  uint32_t titleFrames = 0;
  std::vector<uint32_t> shown;
  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    const auto now = Clock::now();
    const double dt = seconds(now - last);
    last = now;
    changed = changed || o.frames > 0;  // --frames: every frame traced, to count them
    if (std::exchange(input.home, false)) {
      camera = sceneCamera(o.scene, in, aspectOf(w.swapchain));
      lastMove = now;
      changed = true;
    }
    if (moveCamera(window, camera, input, mouse, dt, w.swapchain.extent.height)) {
      lastMove = now;
      changed = true;
    }
    for (const int toggled : input.toggled) {
      Scene& s = o.scene;
      if (toggled == 1) s.shadows = !s.shadows;
      if (toggled == 2) s.reflections = !s.reflections;
      if (toggled == 3) s.refractions = !s.refractions;
      if (toggled == 9) pss.exact = !pss.exact;
      changed = true;
    }
    input.toggled.clear();
    reloadScene(options, input, o.scene, sceneTime, [&](Scene&) { changed = true; });
    if (!fitToWindow(window, w, stale)) continue;  // minimized
    const uint32_t width = w.swapchain.extent.width, height = w.swapchain.extent.height;
    if (shown.size() != size_t(width) * height) changed = true;
    const bool moving = seconds(now - lastMove) < kRest;
    // What to trace: a reduced picture while moving, the full one once the camera rests.
    uint32_t want = 0;
    if (moving && changed) {
      if (pixelsPerSecond > 0.0)
        scale = std::clamp(
            uint32_t(std::ceil(std::sqrt(double(width) * height / (pixelsPerSecond * kMovingFrame)))),
            1u, kMaxScale);
      want = scale;
    } else if (!moving && (changed || drawnScale != 1)) {
      want = 1;
    }
    if (want == 0) {
      glfwWaitEventsTimeout(0.02);
      continue;
    }
    o.width = (width + want - 1) / want;
    o.height = (height + want - 1) / want;
    const auto t0 = Clock::now();
    std::vector<uint32_t> pixels = renderer.render(pssRender(o, pss, in, scene, camera));
    const double took = seconds(Clock::now() - t0);
    pixelsPerSecond = double(o.width) * o.height / std::max(took, 1e-6);
    frameSeconds += took;
    ++titleFrames;
    if (want > 1) pixels = enlarged(pixels, o.width, width, height, want);
    stale = w.show(pixels);
    shown = std::move(pixels);
    drawnScale = want;
    changed = false;
    if (want == 1) ++frames;  // --frames counts the full pictures
    if (frames == 1 && want == 1 && titleFrames == 1)
      fmt::print("iso view: first full picture {:.2f} s after opening ({:.2f} s to trace)\n",
                 seconds(Clock::now() - opened), took);
    const bool lastFrame =
        (o.frames > 0 && frames >= o.frames) || glfwWindowShouldClose(window);
    saveScreenshots(input, o, lastFrame, width, height, shown, screenshots);
    const double sinceTitle = seconds(Clock::now() - titleTime);
    if (sinceTitle > 0.5 || lastFrame) {
      const std::string text = fmt::format(
          "{} | {:.1f} ms a picture{} | point set surface, {} mode | {} points{} | shadows {} | "
          "GPU memory {:.1f} MiB",
          title, frameSeconds / titleFrames * 1e3,
          drawnScale > 1 ? fmt::format(" (1/{} size while moving)", drawnScale) : "",
          modeName(pss), scene.surface->size(), scene.volume ? " and a volume" : "",
          o.scene.shadows ? "on" : "off", double(w.gpu.memoryInUse) / (1 << 20));
      glfwSetWindowTitle(window, text.c_str());
      if (lastFrame) fmt::print("{}\n", text);
      std::fflush(stdout);
      titleTime = Clock::now();
      titleFrames = 0;
      frameSeconds = 0.0;
    }
    if (lastFrame) {
      ended = true;
      break;
    }
  }
  // Closed while nothing was traced (the picture shown is the last): its --screenshot.
  if (!ended && !shown.empty() && !o.screenshot.empty())
    saveScreenshots(input, o, true, w.swapchain.extent.width, w.swapchain.extent.height, shown,
                    screenshots);
  vkDeviceWaitIdle(w.gpu.device);
  if (*w.gpu.validationErrors == 0) return 0;
  fmt::print(stderr, "iso view: {} Vulkan validation errors\n", w.gpu.validationErrors->load());
  return 1;
}

}  // namespace iso::viewer
