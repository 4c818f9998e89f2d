// What the windows of `iso view` share (window.cpp draws the tracer's frames, image_window.cpp
// image-space points): GLFW, the swapchain, input, the camera's mouse and keys, and the copy of a
// picture buffer to the screen.
#pragma once

#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>

#include <algorithm>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "viewer/scene.h"
#include "viewer/view.h"
#include "viewer/vulkan.h"

namespace iso::viewer {

struct Input {
  double wheel = 0;
  bool screenshot = false, reload = false;
  bool home = false;  // back to the view the window started at (Home or 0)
  // Switches pressed since the last frame, in order: 1 shadows, 2 reflections, 3 refractions,
  // 4 back faces (next mode), 5 draw (K), 6 caustics, 7 shading mode (M), 8 layers (L),
  // 9 exact or fast point set surfaces (X)
  std::vector<int> toggled;
  int samples = 0;  // +1 / -1
};

struct Swapchain {
  Owned<VkSwapchainKHR> swapchain;
  VkFormat format = VK_FORMAT_UNDEFINED;
  VkExtent2D extent{};
  std::vector<VkImage> images;
};
// Its width / height.
inline double aspectOf(const Swapchain& s) {
  return double(s.extent.width) / double(std::max(s.extent.height, 1u));
}

// A swapchain for the surface at the window's size (width × height when the surface leaves it
// to us), replacing `old` when given.
Swapchain createSwapchain(Gpu& gpu, VkSurfaceKHR surface, uint32_t width, uint32_t height,
                          VkSwapchainKHR old = VK_NULL_HANDLE);

// Record the copy of a picture (`buffer`, width × height words) into a swapchain image, with the
// image's layout changes around it (undefined before, presentable after).
void recordCopyToSwapchain(VkCommandBuffer cb, VkBuffer buffer, uint32_t width, uint32_t height,
                           VkImage image);

// Present swapchain image `index` once `rendered` is signalled. Returns whether the swapchain no
// longer matches the window.
bool present(Gpu& gpu, const Swapchain& swapchain, uint32_t index, VkSemaphore rendered);

// RGBA words as the swapchain's BGRA, or back (the same swap).
std::vector<uint32_t> toRgba(std::vector<uint32_t> pixels, bool bgra);

// The window's callbacks write what was pressed into `input` (the window's user pointer).
void listen(GLFWwindow* window, Input& input);

struct Mouse {
  double x = 0, y = 0;  // where it was at the last frame
};

// The camera after dt seconds of mouse and keys: left drag orbits, right or middle drag pans (a
// pixel of a picture `height` pixels high), the wheel zooms, W A S D Q E fly. Returns whether it
// moved.
bool moveCamera(GLFWwindow* window, Camera& cam, Input& input, Mouse& mouse, double dt,
                uint32_t height);

// A semaphore per frame slot (an image acquired for the slot's frame) or per swapchain image
// (its frame rendered, for the presentation to wait on).
std::vector<Owned<VkSemaphore>> semaphores(Gpu& gpu, size_t count);

// The window's surface, which the device must be able to present to.
Owned<VkSurfaceKHR> surfaceOf(Gpu& gpu, GLFWwindow* window);

// The scene file, reloaded on R or when it changes on disk (its time was `sceneTime`): the
// command line's scene, the file over it, then `complete` (the camera kept, what the window
// adds); a file that fails keeps the scene as it was.
void reloadScene(const ViewOptions& options, Input& input, Scene& scene,
                 std::filesystem::file_time_type& sceneTime,
                 const std::function<void(Scene& next)>& complete);

// A window's device side `w` (its `swapchain` and `resize(width, height)`) fitted to the
// window: false while it is minimized (after waiting for events); otherwise true, with the
// swapchain made again when the window's size changed or it is `stale`.
template <class WindowGpu>
bool fitToWindow(GLFWwindow* window, WindowGpu& w, bool stale) {
  int width = 0, height = 0;
  glfwGetFramebufferSize(window, &width, &height);
  if (width == 0 || height == 0) {
    glfwWaitEvents();
    return false;
  }
  if (stale || uint32_t(width) != w.swapchain.extent.width ||
      uint32_t(height) != w.swapchain.extent.height)
    w.resize(uint32_t(width), uint32_t(height));
  return true;
}

// Shows pictures made on the host (RGBA words, the swapchain's size): each is copied into a
// host-visible buffer, from there into an acquired swapchain image, and presented; the host
// waits for the copy, so nothing of it is in flight afterwards.
class PictureShow {
 public:
  explicit PictureShow(Gpu& gpu);
  // `rendered`: a semaphore per swapchain image, which the presentation waits on. Returns
  // whether the swapchain no longer matches the window.
  bool show(const Swapchain& swapchain, const std::vector<Owned<VkSemaphore>>& rendered,
            const std::vector<uint32_t>& rgba);

 private:
  Gpu& gpu_;
  Buffer staging_;  // the picture in the swapchain's byte order
  VkCommandBuffer cb_ = VK_NULL_HANDLE;
  Owned<VkFence> copied_;
  Owned<VkSemaphore> acquired_;
};

// The options of a device that presents to GLFW windows.
GpuOptions windowGpuOptions(const ViewOptions& o);

// GLFW, initialized, and one window without a graphics API (Vulkan draws into it), for as long
// as this lives.
class GlfwWindow {
 public:
  GlfwWindow(uint32_t width, uint32_t height, const std::string& title);
  ~GlfwWindow();
  GlfwWindow(const GlfwWindow&) = delete;
  GlfwWindow& operator=(const GlfwWindow&) = delete;
  GLFWwindow* window() const { return window_; }

 private:
  GLFWwindow* window_ = nullptr;
};

// The device side of a window that shows pictures made elsewhere (image-space points, point set
// surfaces): the swapchain, a host-visible copy of the picture for it, and what orders a frame's
// copy and presentation.
struct PictureWindowGpu {
  Gpu gpu;
  Owned<VkSurfaceKHR> surface;
  Swapchain swapchain;
  std::vector<Owned<VkSemaphore>> rendered;  // per swapchain image
  PictureShow picture;

  PictureWindowGpu(GLFWwindow* window, const ViewOptions& o)
      : gpu(createGpu(windowGpuOptions(o))),
        surface(surfaceOf(gpu, window)),
        swapchain(createSwapchain(gpu, surface, o.width, o.height)),
        rendered(semaphores(gpu, swapchain.images.size())),
        picture(gpu) {}

  bool bgra() const { return swapchain.format == VK_FORMAT_B8G8R8A8_UNORM; }

  void resize(uint32_t width, uint32_t height) {
    ISO_VK(vkDeviceWaitIdle(gpu.device));
    swapchain = createSwapchain(gpu, surface, width, height, swapchain.swapchain);
    rendered = semaphores(gpu, swapchain.images.size());
  }

  // Show a picture of the swapchain's size (RGBA words). Returns whether the swapchain no
  // longer matches the window.
  bool show(const std::vector<uint32_t>& rgba) { return picture.show(swapchain, rendered, rgba); }
};

// The screenshots a window takes of the picture it shows (width × height RGBA words): P asked
// for one (input.screenshot, then cleared: iso-screenshot-N.png, N counting in `taken`), and the
// last frame's (--screenshot) when `lastFrame`.
void saveScreenshots(Input& input, const ViewOptions& options, bool lastFrame, uint32_t width,
                     uint32_t height, const std::vector<uint32_t>& picture, uint32_t& taken);

// A picture `from` pixels wide shown `scale` times larger, cut to width × height.
std::vector<uint32_t> enlarged(const std::vector<uint32_t>& pixels, uint32_t from, uint32_t width,
                               uint32_t height, uint32_t scale);

}  // namespace iso::viewer
