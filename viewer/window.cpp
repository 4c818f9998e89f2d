// `iso view FILE`: a GLFW window with a Vulkan swapchain; each frame traces into the output
// buffer and copies it to the swapchain image (compute only, no graphics pipeline).
//
// Mouse: left drag orbits, right or middle drag pans, the wheel zooms. Keys: W A S D fly, Q E
// down and up, 1 shadows, 2 reflections, 3 refractions, B back faces (shown, tinted, hidden),
// K what is drawn (surface, kept points as splats, both, and the kept points as image-space
// points: image_window.cpp's drawing, in this window), + and - samples per pixel, P
// screenshot, R reloads the scene file (it also reloads by itself when the file changes), Home or
// 0 goes back to the view it started at, Esc quits.
#include <fmt/core.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <future>

#include "viewer/asset.h"
#include "base/image.h"
#include "viewer/image_view.h"
#include "viewer/point_image_gpu.h"
#include "viewer/renderer.h"
#include "viewer/view.h"
#include "viewer/window_parts.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;

// Keys 1, 2, 3, B, K, C, L, + and -. C turns the caustics of --caustics N off and on. K steps
// through what is drawn, the image-space mode last when the window has one (`image`). L steps
// through the lighting of a file with baked lighting (baked, live, both).
void applySwitches(Input& input, Scene& scene, uint32_t photons, bool* image) {
  for (const int toggled : input.toggled) {
    if (toggled == 1) scene.shadows = !scene.shadows;
    if (toggled == 2) scene.reflections = !scene.reflections;
    if (toggled == 3) scene.refractions = !scene.refractions;
    if (toggled == 4) scene.backFaces = BackFaces((int(scene.backFaces) + 1) % 3);
    if (toggled == 5 && image && *image) {
      *image = false;
      scene.draw = Draw::Surface;
    } else if (toggled == 5 && image && scene.draw == Draw::Both) {
      *image = true;
    } else if (toggled == 5) {
      scene.draw = Draw((int(scene.draw) + 1) % 3);
    }
    if (toggled == 6 && photons == 0)
      fmt::print("iso view: no caustics to show (start with --caustics N)\n");
    if (toggled == 6) scene.caustics = scene.caustics > 0 ? 0 : photons;
    if (toggled == 8) {
      scene.lighting = scene.lighting == Lighting::Auto || scene.lighting == Lighting::Baked
                           ? Lighting::Live
                           : (scene.lighting == Lighting::Live ? Lighting::Both : Lighting::Baked);
      fmt::print("iso view: lighting {} (drawn so when the file has baked lighting)\n",
                 nameOf(kLightingNames, scene.lighting));
    }
  }
  input.toggled.clear();
  if (input.samples != 0) scene.samples = std::clamp(scene.samples + input.samples, 1, 64);
  input.samples = 0;
}

// Record the copy of the prepared frame's picture into swapchain image `index` (acquired,
// signalling `acquired`), submit the frame (signalling `rendered`) and present the image. The
// host does not wait for it. Returns whether the swapchain no longer matches the window.
bool drawAndPresent(Gpu& gpu, Renderer& renderer, const Swapchain& swapchain, uint32_t index,
                    VkSemaphore acquired, VkSemaphore rendered) {
  VkCommandBuffer cb = renderer.record();
  recordCopyToSwapchain(cb, renderer.output().buffer, renderer.setup().width,
                        renderer.setup().height, swapchain.images[index]);
  renderer.submit(acquired, VK_PIPELINE_STAGE_TRANSFER_BIT, rendered);
  return present(gpu, swapchain, index, rendered);
}

// The renderer of a window: the swapchain's size, and room in the output for the window at the
// screen's size, so that resizing needs no new GPU memory (the budget holds for any size up to
// it).
RendererOptions windowRendererOptions(const ViewOptions& options, const Swapchain& swapchain) {
  RendererOptions ro;
  ro.width = swapchain.extent.width;
  ro.height = swapchain.extent.height;
  const GLFWvidmode* mode = glfwGetVideoMode(glfwGetPrimaryMonitor());
  ro.capacityWidth = std::max(ro.width, mode ? uint32_t(mode->width) : 0u);
  ro.capacityHeight = std::max(ro.height, mode ? uint32_t(mode->height) : 0u);
  ro.vram = options.vram;
  ro.uploadBytes = options.uploadBytes;
  ro.pss = options.pss.get();
  ro.framesInFlight = options.framesInFlight;
  ro.swapRedBlue = swapchain.format == VK_FORMAT_B8G8R8A8_UNORM;
  ro.caustics = options.scene.caustics > 0;
  return ro;
}

// The frames collected since the title last changed.
struct TitleStats {
  uint32_t frames = 0;
  uint64_t rays = 0;
  double dispatchSeconds = 0;  // from timestamps (0 without them)
};

// ms a frame and fps are the wall time between frames (frames in flight overlap); rays/s are
// over the dispatches' GPU time when the queue has timestamps, else over the wall time.
std::string titleText(const std::string& title, const TitleStats& t, double seconds,
                      const FrameStats& s) {
  const uint32_t frames = std::max(t.frames, 1u);
  const double raySeconds = t.dispatchSeconds > 0 ? t.dispatchSeconds : seconds;
  return fmt::format(
      "{} | {:.1f} ms ({:.0f} fps) | {:.1f} Mrays/s | GPU memory {:.1f} MiB | chunks {} "
      "resident, {} requested",
      title, seconds / frames * 1e3, t.frames / seconds, t.rays / std::max(raySeconds, 1e-9) / 1e6,
      s.vramInUse / 1048576.0, s.resident, s.pending);
}

// The window's GPU side: the device, the surface and its swapchain, the semaphores of the frames
// in flight, and the renderer; destroyed in reverse order (the renderer first: it waits for the
// device).
struct WindowGpu {
  Gpu gpu;
  Owned<VkSurfaceKHR> surface;
  Swapchain swapchain;
  RendererOptions options;
  std::vector<Owned<VkSemaphore>> acquired;  // per frame slot
  std::vector<Owned<VkSemaphore>> rendered;  // per swapchain image
  Renderer renderer;

  WindowGpu(GLFWwindow* window, const ViewOptions& o, const Asset& asset, const Environment* env)
      : gpu(createGpu(windowGpuOptions(o))),
        surface(surfaceOf(gpu, window)),
        swapchain(createSwapchain(gpu, surface, o.width, o.height)),
        options(windowRendererOptions(o, swapchain)),
        acquired(semaphores(gpu, options.framesInFlight)),
        rendered(semaphores(gpu, swapchain.images.size())),
        renderer(gpu, asset, env, options) {}


  // A new swapchain at the window's size, once the frames in flight are done; the renderer draws
  // at that size (at the capacity beyond the screen's size, on another monitor).
  void resize(uint32_t width, uint32_t height) {
    renderer.finish();
    ISO_VK(vkDeviceWaitIdle(gpu.device));
    swapchain = createSwapchain(gpu, surface, width, height,
                                swapchain.swapchain);  // the old one goes after
    rendered = semaphores(gpu, swapchain.images.size());
    renderer.resize(std::min(swapchain.extent.width, options.capacityWidth),
                    std::min(swapchain.extent.height, options.capacityHeight));
  }

  // Trace the prepared frame and show it. Returns whether the swapchain no longer matches the
  // window. An image that cannot be acquired leaves the frame traced and not shown.
  bool draw() {
    // prepare() waited for the frame that last used this slot, and so for its acquisition.
    VkSemaphore slotAcquired = acquired[renderer.slot()];
    uint32_t index = 0;
    const VkResult acquire = vkAcquireNextImageKHR(gpu.device, swapchain.swapchain, UINT64_MAX,
                                                   slotAcquired, VK_NULL_HANDLE, &index);
    if (acquire == VK_ERROR_OUT_OF_DATE_KHR) {
      renderer.record();
      renderer.submit();
      return true;
    }
    if (acquire != VK_SUCCESS && acquire != VK_SUBOPTIMAL_KHR)
      checkVk(acquire, "vkAcquireNextImageKHR");
    return drawAndPresent(gpu, renderer, swapchain, index, slotAcquired, rendered[index]) ||
           acquire == VK_SUBOPTIMAL_KHR;
  }
};

// The window's image-space mode: the kept points, read and put on the device the first time the
// mode is asked for, and shown as pictures.
struct ImageMode {
  const WindowImageMode* mode = nullptr;
  bool failed = false;  // the file has no points to draw that way (said once)
  std::future<std::shared_ptr<const ImageInputs>> reading;  // beside the window
  std::shared_ptr<const ImageInputs> inputs;
  std::unique_ptr<PointImageScene> scene;
  std::unique_ptr<GpuPointImage> renderer;  // draws *scene
  std::unique_ptr<PictureShow> show;
  std::vector<uint32_t> lastPicture;  // RGBA, the swapchain's size
  double frameSeconds = 0.0;          // drawing, since the title changed
  uint32_t frames = 0;                // since the title changed

  // Whether the kept points are on the device. The first call starts reading them beside the
  // window (which goes on drawing the surface); false until they are read, and for good when
  // that failed (`failed`, the reader's error printed).
  bool ready(Gpu& gpu, const Scene& sceneNow) {
    if (renderer) return true;
    if (failed) return false;
    if (!reading.valid()) {
      fmt::print("iso view: reading the kept points\n");
      reading = std::async(std::launch::async, mode->read);
    }
    if (reading.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return false;
    try {
      inputs = reading.get();
      scene = std::make_unique<PointImageScene>(withOpacity(inputs->objects, sceneNow.image));
      renderer = std::make_unique<GpuPointImage>(gpu, *scene);
      show = std::make_unique<PictureShow>(gpu);
    } catch (const std::exception& e) {
      fmt::print(stderr, "iso view: {}\n", e.what());
      failed = true;
      return false;
    }
    fmt::print("iso view: drawing {} kept points as image-space points (K again: the surface)\n",
               scene->size());
    return true;
  }

  // Draws the kept points from the scene's camera into the window. Returns whether the
  // swapchain no longer matches the window.
  bool draw(const ViewOptions& options, const Scene& sceneNow, const Swapchain& swapchain,
            const std::vector<Owned<VkSemaphore>>& rendered) {
    const auto lights = lightsOf(sceneNow, *inputs, *sceneNow.camera);
    ViewOptions sized = options;
    sized.width = swapchain.extent.width;
    sized.height = swapchain.extent.height;
    const ImageSettings settings =
        budgeted(settingsOf(sceneNow, *mode->options), sized, scene->size(), lights.size());
    const auto t0 = Clock::now();
    GpuImageFrame frame = renderer->render(
        cameraOf(*inputs, *sceneNow.camera, sized.width, sized.height), lights, settings);
    frameSeconds += std::chrono::duration<double>(Clock::now() - t0).count();
    ++frames;
    const bool stale = show->show(swapchain, rendered, frame.pixels);
    lastPicture = std::move(frame.pixels);
    return stale;
  }
};

// Save the last frame drawn (this waits for the frames in flight).
void saveScreenshot(const std::filesystem::path& file, Renderer& renderer, bool bgra) {
  const std::vector<uint32_t> pixels = toRgba(renderer.pixels(), bgra);
  writeRgba8Image(file, renderer.setup().width, renderer.setup().height, pixels);
  fmt::print("iso view: saved {}\n", file.string());
  std::fflush(stdout);  // a session watching the output sees it now
}

}  // namespace

int viewWindow(const ViewOptions& options, const WindowImageMode& image) {
  const auto asset = Asset::open(options.file);
  Scene scene = completeScene(options, *asset);
  std::optional<Environment> env;
  if (!scene.environment.empty()) env = loadEnvironment(scene.environment);

  const std::string title = "iso view " + options.file.filename().string();
  const GlfwWindow glfw(options.width, options.height, title);
  GLFWwindow* window = glfw.window();
  WindowGpu w(window, options, *asset, env ? &*env : nullptr);
  Renderer& renderer = w.renderer;
  const bool bgra = w.swapchain.format == VK_FORMAT_B8G8R8A8_UNORM;
  TitleStats shownStats;
  renderer.onCollected([&](const FrameStats& s) {
    ++shownStats.frames;
    shownStats.rays += s.rays.total();
    shownStats.dispatchSeconds += s.dispatchSeconds;
  });

  Input input;
  listen(window, input);
  std::filesystem::file_time_type sceneTime{};
  if (!options.sceneFile.empty()) sceneTime = std::filesystem::last_write_time(options.sceneFile);
  bool stale = false;  // the swapchain no longer matches the window
  Mouse mouse;
  glfwGetCursorPos(window, &mouse.x, &mouse.y);
  auto last = Clock::now(), titleTime = last;
  uint32_t frames = 0, screenshots = 0;
  const auto header = asset->reader.header();
  ImageMode drawImage;
  drawImage.mode = &image;
  bool imageOn = false, pointsShown = false;
  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    const auto now = Clock::now();
    const double dt = std::chrono::duration<double>(now - last).count();
    last = now;
    if (std::exchange(input.home, false))
      scene.camera = startCamera(options, *asset, aspectOf(w.swapchain));
    moveCamera(window, *scene.camera, input, mouse, dt, w.swapchain.extent.height);
    applySwitches(input, scene, options.scene.caustics, image.read ? &imageOn : nullptr);
    reloadScene(options, input, scene, sceneTime, [&](Scene& next) {
      if (next.lights.empty()) next.lights.push_back(defaultLight(*next.camera, asset->bounds));
      placeGround(next, *asset);
    });
    if (!fitToWindow(window, w, stale)) continue;  // minimized
    // Image-space points once they are read; the surface meanwhile.
    const bool points = imageOn && drawImage.ready(w.gpu, scene);
    if (imageOn && drawImage.failed) {
      imageOn = false;
      scene.draw = Draw::Surface;
    }
    if (points && !pointsShown) renderer.finish();  // the traced frames in flight go first
    pointsShown = points;
    if (points) {
      stale = drawImage.draw(options, scene, w.swapchain, w.rendered);
    } else {
      renderer.prepare(frameParams(scene, header.frame, header.maxLevel, renderer.setup()));
      stale = w.draw();
    }
    ++frames;
    // The last frame: --frames reached, or the window asked to close (Escape, its close button)
    // while this one was prepared.
    const bool lastFrame =
        (options.frames > 0 && frames >= options.frames) || glfwWindowShouldClose(window);
    const auto save = [&](const std::filesystem::path& file) {
      if (!points) return saveScreenshot(file, renderer, bgra);
      writeRgba8Image(file, w.swapchain.extent.width, w.swapchain.extent.height, drawImage.lastPicture);
      fmt::print("iso view: saved {}\n", file.string());
      std::fflush(stdout);  // a session watching the output sees it now
    };
    if (input.screenshot) save(fmt::format("iso-screenshot-{}.png", ++screenshots));
    input.screenshot = false;
    if (lastFrame && !options.screenshot.empty()) save(options.screenshot);
    if (lastFrame) renderer.finish();
    const double sinceTitle = std::chrono::duration<double>(Clock::now() - titleTime).count();
    if (sinceTitle > 0.5 || lastFrame) {
      const std::string text =
          !points ? titleText(title, shownStats, sinceTitle, renderer.stats())
                   : fmt::format("{} | image-space points | {:.1f} ms a frame | {} points", title,
                                 drawImage.frameSeconds * 1e3 / std::max(drawImage.frames, 1u),
                                 drawImage.scene->size());
      glfwSetWindowTitle(window, text.c_str());
      if (lastFrame) fmt::print("{}\n", text);
      titleTime = Clock::now();
      shownStats = {};
      drawImage.frames = 0;
      drawImage.frameSeconds = 0.0;
    }
    if (lastFrame) break;
  }
  renderer.finish();
  vkDeviceWaitIdle(w.gpu.device);
  renderer.onCollected({});
  if (*w.gpu.validationErrors == 0) return 0;
  fmt::print(stderr, "iso view: {} Vulkan validation errors\n", w.gpu.validationErrors->load());
  return 1;
}

}  // namespace iso::viewer
