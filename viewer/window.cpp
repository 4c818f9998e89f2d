// `iso view FILE`: a GLFW window with a Vulkan swapchain; each frame traces into the output
// buffer and copies it to the swapchain image (compute only, no graphics pipeline).
//
// Mouse: left drag orbits, right or middle drag pans, the wheel zooms. Keys: W A S D fly, Q E
// down and up, 1 shadows, 2 reflections, 3 refractions, B back faces (shown, tinted, hidden),
// K what is drawn (surface, kept points as splats, both), + and - samples per pixel, P
// screenshot, R reloads the scene file (it also reloads by itself
// when the file changes), Esc quits.
#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>
#include <fmt/core.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include "viewer/asset.h"
#include "viewer/image.h"
#include "viewer/renderer.h"
#include "viewer/view.h"

namespace iso::viewer {
namespace {

using Clock = std::chrono::steady_clock;

struct Input {
  double wheel = 0;
  bool screenshot = false, reload = false;
  // 1 shadows, 2 reflections, 3 refractions, 4 back faces (next mode), 5 draw, 6 caustics
  int toggled = 0;
  int samples = 0;  // +1 / -1
};

struct Swapchain {
  Owned<VkSwapchainKHR> swapchain;
  VkFormat format = VK_FORMAT_UNDEFINED;
  VkExtent2D extent{};
  std::vector<VkImage> images;
};

// A swapchain for the surface at the window's size (width × height when the surface leaves it
// to us), replacing `old` when given.
Swapchain createSwapchain(Gpu& gpu, VkSurfaceKHR surface, uint32_t width, uint32_t height,
                          VkSwapchainKHR old = VK_NULL_HANDLE) {
  Swapchain s;
  VkSurfaceCapabilitiesKHR caps;
  ISO_VK(vkGetPhysicalDeviceSurfaceCapabilitiesKHR(gpu.physical, surface, &caps));
  if (!(caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_DST_BIT))
    throw std::runtime_error("the window's swapchain images cannot be copied to");
  uint32_t count = 0;
  ISO_VK(vkGetPhysicalDeviceSurfaceFormatsKHR(gpu.physical, surface, &count, nullptr));
  std::vector<VkSurfaceFormatKHR> formats(count);
  ISO_VK(vkGetPhysicalDeviceSurfaceFormatsKHR(gpu.physical, surface, &count, formats.data()));
  for (const auto& f : formats)  // the tracer writes sRGB-encoded bytes: a UNORM format
    if (f.format == VK_FORMAT_B8G8R8A8_UNORM || f.format == VK_FORMAT_R8G8B8A8_UNORM) {
      s.format = f.format;
      break;
    }
  if (s.format == VK_FORMAT_UNDEFINED)
    throw std::runtime_error("the window offers no 8-bit RGBA or BGRA swapchain format");
  s.extent =
      caps.currentExtent.width != UINT32_MAX ? caps.currentExtent : VkExtent2D{width, height};
  VkSwapchainCreateInfoKHR info{VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR};
  info.surface = surface;
  info.minImageCount = std::max(caps.minImageCount, 2u);
  if (caps.maxImageCount) info.minImageCount = std::min(info.minImageCount, caps.maxImageCount);
  info.imageFormat = s.format;
  info.imageColorSpace = VK_COLOR_SPACE_SRGB_NONLINEAR_KHR;
  info.imageExtent = s.extent;
  info.imageArrayLayers = 1;
  info.imageUsage = VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  info.preTransform = caps.currentTransform;
  info.compositeAlpha = VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR;
  info.presentMode = VK_PRESENT_MODE_FIFO_KHR;
  info.clipped = VK_TRUE;
  info.oldSwapchain = old;
  VkSwapchainKHR handle;
  ISO_VK(vkCreateSwapchainKHR(gpu.device, &info, nullptr, &handle));
  VkDevice device = gpu.device;
  s.swapchain = {handle, [device](VkSwapchainKHR h) { vkDestroySwapchainKHR(device, h, nullptr); }};
  ISO_VK(vkGetSwapchainImagesKHR(gpu.device, handle, &count, nullptr));
  s.images.resize(count);
  ISO_VK(vkGetSwapchainImagesKHR(gpu.device, handle, &count, s.images.data()));
  return s;
}

void imageBarrier(VkCommandBuffer cb, VkImage image, VkImageLayout from, VkImageLayout to,
                  VkAccessFlags srcAccess, VkAccessFlags dstAccess) {
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.oldLayout = from;
  b.newLayout = to;
  b.srcAccessMask = srcAccess;
  b.dstAccessMask = dstAccess;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image;
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT,
                       0, 0, nullptr, 0, nullptr, 1, &b);
}

std::vector<uint32_t> toRgba(std::vector<uint32_t> pixels, bool bgra) {
  if (bgra)
    for (uint32_t& p : pixels) p = (p & 0xFF00FF00u) | (p & 0xFFu) << 16 | (p >> 16 & 0xFFu);
  return pixels;
}

// The window's callbacks write what was pressed into `input` (the window's user pointer).
void listen(GLFWwindow* window, Input& input) {
  glfwSetWindowUserPointer(window, &input);
  glfwSetScrollCallback(window, [](GLFWwindow* w, double, double dy) {
    static_cast<Input*>(glfwGetWindowUserPointer(w))->wheel += dy;
  });
  glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int) {
    if (action != GLFW_PRESS) return;
    Input& in = *static_cast<Input*>(glfwGetWindowUserPointer(w));
    if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(w, GLFW_TRUE);
    if (key == GLFW_KEY_P || key == GLFW_KEY_F12) in.screenshot = true;
    if (key == GLFW_KEY_R) in.reload = true;
    if (key == GLFW_KEY_1 || key == GLFW_KEY_2 || key == GLFW_KEY_3) in.toggled = key - GLFW_KEY_0;
    if (key == GLFW_KEY_B) in.toggled = 4;
    if (key == GLFW_KEY_K) in.toggled = 5;
    if (key == GLFW_KEY_C) in.toggled = 6;
    if (key == GLFW_KEY_EQUAL || key == GLFW_KEY_KP_ADD) in.samples = 1;
    if (key == GLFW_KEY_MINUS || key == GLFW_KEY_KP_SUBTRACT) in.samples = -1;
  });
}

struct Mouse {
  double x = 0, y = 0;  // where it was at the last frame
};

// The camera after dt seconds of mouse and keys: left drag orbits, right or middle drag pans (a
// pixel of a picture `height` pixels high), the wheel zooms, W A S D Q E fly.
void moveCamera(GLFWwindow* window, Camera& cam, Input& input, Mouse& mouse, double dt,
                uint32_t height) {
  double x, y;
  glfwGetCursorPos(window, &x, &y);
  const double dx = x - mouse.x, dy = y - mouse.y;
  mouse = {x, y};
  const Vec3d forward = glm::normalize(cam.target - cam.eye);
  const Vec3d right = glm::normalize(glm::cross(forward, cam.up));
  const Vec3d up = glm::cross(right, forward);
  const double distance = glm::length(cam.target - cam.eye);
  if (glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) {
    Vec3d offset = cam.eye - cam.target;
    offset = rotated(offset, glm::normalize(cam.up), -dx * 0.008);
    const Vec3d pitched = rotated(offset, right, -dy * 0.008);
    if (std::abs(glm::dot(glm::normalize(pitched), glm::normalize(cam.up))) < 0.98)
      offset = pitched;
    cam.eye = cam.target + offset;
  }
  if (glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS ||
      glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS) {
    const double k = distance * 2 * std::tan(cam.fovDegrees * M_PI / 360) / height;
    const Vec3d move = right * (-dx * k) + up * (dy * k);
    cam.eye = cam.eye + move;
    cam.target = cam.target + move;
  }
  if (input.wheel != 0) {
    cam.eye = cam.target + (cam.eye - cam.target) * std::pow(0.9, input.wheel);
    input.wheel = 0;
  }
  Vec3d fly{0, 0, 0};
  if (glfwGetKey(window, GLFW_KEY_W) == GLFW_PRESS) fly = fly + forward;
  if (glfwGetKey(window, GLFW_KEY_S) == GLFW_PRESS) fly = fly - forward;
  if (glfwGetKey(window, GLFW_KEY_D) == GLFW_PRESS) fly = fly + right;
  if (glfwGetKey(window, GLFW_KEY_A) == GLFW_PRESS) fly = fly - right;
  if (glfwGetKey(window, GLFW_KEY_E) == GLFW_PRESS) fly = fly + up;
  if (glfwGetKey(window, GLFW_KEY_Q) == GLFW_PRESS) fly = fly - up;
  if (glm::dot(fly, fly) > 0) {
    const Vec3d move = fly * (0.5 * distance * std::min(dt, 0.1));
    cam.eye = cam.eye + move;
    cam.target = cam.target + move;
  }
}

// Keys 1, 2, 3, B, K, C, + and -. C turns the caustics of --caustics N off and on.
void applySwitches(Input& input, Scene& scene, uint32_t photons) {
  if (input.toggled == 1) scene.shadows = !scene.shadows;
  if (input.toggled == 2) scene.reflections = !scene.reflections;
  if (input.toggled == 3) scene.refractions = !scene.refractions;
  if (input.toggled == 4) scene.backFaces = BackFaces((int(scene.backFaces) + 1) % 3);
  if (input.toggled == 5) scene.draw = Draw((int(scene.draw) + 1) % 3);
  if (input.toggled == 6 && photons == 0)
    fmt::print("iso view: no caustics to show (start with --caustics N)\n");
  if (input.toggled == 6) scene.caustics = scene.caustics > 0 ? 0 : photons;
  input.toggled = 0;
  if (input.samples != 0) scene.samples = std::clamp(scene.samples + input.samples, 1, 64);
  input.samples = 0;
}

// The scene file: reloaded on R or when it changes (its time was `sceneTime`); the camera stays
// where it is, and a file that fails keeps the scene as it was.
void reloadScene(const ViewOptions& options, const Asset& asset, Input& input, Scene& scene,
                 std::filesystem::file_time_type& sceneTime) {
  if (options.sceneFile.empty()) return;
  std::error_code ec;
  const auto t = std::filesystem::last_write_time(options.sceneFile, ec);
  if (input.reload || (!ec && t != sceneTime)) {
    sceneTime = t;
    Scene next = options.scene;
    try {
      loadScene(options.sceneFile, next);
      next.camera = scene.camera;
      if (next.lights.empty()) next.lights.push_back(defaultLight(*next.camera, asset.bounds));
      placeGround(next, asset);
      scene = next;
      fmt::print("iso view: reloaded {}\n", options.sceneFile.string());
    } catch (const std::exception& e) {
      fmt::print(stderr, "iso view: {} (kept the previous scene)\n", e.what());
    }
  }
  input.reload = false;
}

// Record the copy of the prepared frame's picture into swapchain image `index` (acquired,
// signalling `acquired`), submit the frame (signalling `rendered`) and present the image. The
// host does not wait for it. Returns whether the swapchain no longer matches the window.
bool drawAndPresent(Gpu& gpu, Renderer& renderer, const Swapchain& swapchain, uint32_t index,
                    VkSemaphore acquired, VkSemaphore rendered) {
  VkCommandBuffer cb = renderer.record();
  VkImage image = swapchain.images[index];
  imageBarrier(cb, image, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0,
               VK_ACCESS_TRANSFER_WRITE_BIT);
  VkBufferImageCopy copy{};
  copy.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  copy.bufferRowLength = renderer.setup().width;
  copy.imageExtent = {renderer.setup().width, renderer.setup().height, 1};
  vkCmdCopyBufferToImage(cb, renderer.output().buffer, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                         1, &copy);
  imageBarrier(cb, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR,
               VK_ACCESS_TRANSFER_WRITE_BIT, 0);
  renderer.submit(acquired, VK_PIPELINE_STAGE_TRANSFER_BIT, rendered);
  const VkSwapchainKHR presentTo = swapchain.swapchain;
  VkPresentInfoKHR present{VK_STRUCTURE_TYPE_PRESENT_INFO_KHR};
  present.waitSemaphoreCount = 1;
  present.pWaitSemaphores = &rendered;
  present.swapchainCount = 1;
  present.pSwapchains = &presentTo;
  present.pImageIndices = &index;
  const VkResult presented = vkQueuePresentKHR(gpu.queue, &present);
  const bool stale = presented == VK_ERROR_OUT_OF_DATE_KHR || presented == VK_SUBOPTIMAL_KHR;
  if (!stale) checkVk(presented, "vkQueuePresentKHR");
  return stale;
}

// A semaphore per frame slot (an image acquired for the slot's frame) or per swapchain image
// (its frame rendered, for the presentation to wait on).
std::vector<Owned<VkSemaphore>> semaphores(Gpu& gpu, size_t count) {
  std::vector<Owned<VkSemaphore>> v;
  for (size_t i = 0; i < count; ++i) v.push_back(createSemaphore(gpu));
  return v;
}

// The window's surface, which the device must be able to present to.
Owned<VkSurfaceKHR> surfaceOf(Gpu& gpu, GLFWwindow* window) {
  VkSurfaceKHR handle;
  ISO_VK(glfwCreateWindowSurface(gpu.instance, window, nullptr, &handle));
  VkInstance instance = gpu.instance;
  Owned<VkSurfaceKHR> surface = {
      handle, [instance](VkSurfaceKHR h) { vkDestroySurfaceKHR(instance, h, nullptr); }};
  VkBool32 canPresent = VK_FALSE;
  ISO_VK(vkGetPhysicalDeviceSurfaceSupportKHR(gpu.physical, gpu.queueFamily, handle, &canPresent));
  if (!canPresent) throw std::runtime_error("the Vulkan device cannot present to the window");
  return surface;
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

// GLFW, initialized, and one window without a graphics API (Vulkan draws into it), for as long
// as this lives.
class GlfwWindow {
 public:
  GlfwWindow(uint32_t width, uint32_t height, const std::string& title) {
    if (!glfwInit())
      throw std::runtime_error("cannot open a window (no display?); use --headless --out F.png");
    const char* problem = nullptr;
    if (!glfwVulkanSupported()) {
      problem = "GLFW finds no Vulkan loader";
    } else {
      glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
      window_ = glfwCreateWindow(int(width), int(height), title.c_str(), nullptr, nullptr);
      if (!window_) problem = "cannot open a window (no display?); use --headless";
    }
    if (problem) {
      glfwTerminate();
      throw std::runtime_error(problem);
    }
  }
  ~GlfwWindow() {
    glfwDestroyWindow(window_);
    glfwTerminate();
  }
  GlfwWindow(const GlfwWindow&) = delete;
  GlfwWindow& operator=(const GlfwWindow&) = delete;
  GLFWwindow* window() const { return window_; }

 private:
  GLFWwindow* window_ = nullptr;
};

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
      : gpu(createGpu(gpuOptions(o))),
        surface(surfaceOf(gpu, window)),
        swapchain(createSwapchain(gpu, surface, o.width, o.height)),
        options(windowRendererOptions(o, swapchain)),
        acquired(semaphores(gpu, options.framesInFlight)),
        rendered(semaphores(gpu, swapchain.images.size())),
        renderer(gpu, asset, env, options) {}

  static GpuOptions gpuOptions(const ViewOptions& o) {
    uint32_t extensionCount = 0;
    const char** extensions = glfwGetRequiredInstanceExtensions(&extensionCount);
    GpuOptions g;
    g.instanceExtensions.assign(extensions, extensions + extensionCount);
    g.swapchain = true;
    g.validation = o.validation;
    g.deviceName = o.device;
    return g;
  }

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

// Save the last frame drawn (this waits for the frames in flight).
void saveScreenshot(const std::filesystem::path& file, Renderer& renderer, bool bgra) {
  const std::vector<uint32_t> pixels = toRgba(renderer.pixels(), bgra);
  writeImage(file, renderer.setup().width, renderer.setup().height, pixels);
  fmt::print("iso view: saved {}\n", file.string());
}

}  // namespace

int viewWindow(const ViewOptions& options) {
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
  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    const auto now = Clock::now();
    const double dt = std::chrono::duration<double>(now - last).count();
    last = now;
    moveCamera(window, *scene.camera, input, mouse, dt, w.swapchain.extent.height);
    applySwitches(input, scene, options.scene.caustics);
    reloadScene(options, *asset, input, scene, sceneTime);
    int fbWidth = 0, fbHeight = 0;
    glfwGetFramebufferSize(window, &fbWidth, &fbHeight);
    if (fbWidth == 0 || fbHeight == 0) {  // minimized
      glfwWaitEvents();
      continue;
    }
    if (stale || uint32_t(fbWidth) != w.swapchain.extent.width ||
        uint32_t(fbHeight) != w.swapchain.extent.height)
      w.resize(uint32_t(fbWidth), uint32_t(fbHeight));
    renderer.prepare(frameParams(scene, header.frame, header.maxLevel, renderer.setup()));
    stale = w.draw();
    ++frames;
    // The last frame: --frames reached, or the window asked to close (Escape, its close button)
    // while this one was prepared.
    const bool lastFrame =
        (options.frames > 0 && frames >= options.frames) || glfwWindowShouldClose(window);
    if (input.screenshot)
      saveScreenshot(fmt::format("iso-screenshot-{}.png", ++screenshots), renderer, bgra);
    input.screenshot = false;
    if (lastFrame && !options.screenshot.empty())
      saveScreenshot(options.screenshot, renderer, bgra);
    if (lastFrame) renderer.finish();
    const double sinceTitle = std::chrono::duration<double>(Clock::now() - titleTime).count();
    if (sinceTitle > 0.5 || lastFrame) {
      const std::string text = titleText(title, shownStats, sinceTitle, renderer.stats());
      glfwSetWindowTitle(window, text.c_str());
      if (lastFrame) fmt::print("{}\n", text);
      titleTime = Clock::now();
      shownStats = {};
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
