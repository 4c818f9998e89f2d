// What the windows of `iso view` share (window_parts.h).
#include "viewer/window_parts.h"

#include "base/image.h"

#include <fmt/core.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace iso::viewer {
namespace {

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

}  // namespace

Swapchain createSwapchain(Gpu& gpu, VkSurfaceKHR surface, uint32_t width, uint32_t height,
                          VkSwapchainKHR old) {
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

std::vector<uint32_t> toRgba(std::vector<uint32_t> pixels, bool bgra) {
  if (bgra)
    for (uint32_t& p : pixels) p = (p & 0xFF00FF00u) | (p & 0xFFu) << 16 | (p >> 16 & 0xFFu);
  return pixels;
}

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
    if (key == GLFW_KEY_HOME || key == GLFW_KEY_0) in.home = true;
    if (key == GLFW_KEY_1 || key == GLFW_KEY_2 || key == GLFW_KEY_3) in.toggled.push_back(key - GLFW_KEY_0);
    if (key == GLFW_KEY_B) in.toggled.push_back(4);
    if (key == GLFW_KEY_K) in.toggled.push_back(5);
    if (key == GLFW_KEY_C) in.toggled.push_back(6);
    if (key == GLFW_KEY_M) in.toggled.push_back(7);
    if (key == GLFW_KEY_L) in.toggled.push_back(8);
    if (key == GLFW_KEY_X) in.toggled.push_back(9);
    if (key == GLFW_KEY_EQUAL || key == GLFW_KEY_KP_ADD) in.samples += 1;
    if (key == GLFW_KEY_MINUS || key == GLFW_KEY_KP_SUBTRACT) in.samples -= 1;
  });
}

bool moveCamera(GLFWwindow* window, Camera& cam, Input& input, Mouse& mouse, double dt,
                uint32_t height) {
  const Camera before = cam;
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
  return cam.eye != before.eye || cam.target != before.target;
}

std::vector<Owned<VkSemaphore>> semaphores(Gpu& gpu, size_t count) {
  std::vector<Owned<VkSemaphore>> v;
  for (size_t i = 0; i < count; ++i) v.push_back(createSemaphore(gpu));
  return v;
}

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

void reloadScene(const ViewOptions& options, Input& input, Scene& scene,
                 std::filesystem::file_time_type& sceneTime,
                 const std::function<void(Scene& next)>& complete) {
  if (options.sceneFile.empty()) return;
  std::error_code ec;
  const auto t = std::filesystem::last_write_time(options.sceneFile, ec);
  if (input.reload || (!ec && t != sceneTime)) {
    sceneTime = t;
    Scene next = options.scene;
    try {
      loadScene(options.sceneFile, next);
      next.camera = scene.camera;
      complete(next);
      scene = next;
      fmt::print("iso view: reloaded {}\n", options.sceneFile.string());
      std::fflush(stdout);  // a session watching the output sees it now
    } catch (const std::exception& e) {
      fmt::print(stderr, "iso view: {} (kept the previous scene)\n", e.what());
    }
  }
  input.reload = false;
}

GpuOptions windowGpuOptions(const ViewOptions& o) {
  uint32_t extensionCount = 0;
  const char** extensions = glfwGetRequiredInstanceExtensions(&extensionCount);
  GpuOptions g;
  g.instanceExtensions.assign(extensions, extensions + extensionCount);
  g.swapchain = true;
  g.validation = o.validation;
  g.deviceName = o.device;
  return g;
}

void recordCopyToSwapchain(VkCommandBuffer cb, VkBuffer buffer, uint32_t width, uint32_t height,
                           VkImage image) {
  imageBarrier(cb, image, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 0,
               VK_ACCESS_TRANSFER_WRITE_BIT);
  VkBufferImageCopy copy{};
  copy.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  copy.bufferRowLength = width;
  copy.imageExtent = {width, height, 1};
  vkCmdCopyBufferToImage(cb, buffer, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &copy);
  imageBarrier(cb, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR,
               VK_ACCESS_TRANSFER_WRITE_BIT, 0);
}

bool present(Gpu& gpu, const Swapchain& swapchain, uint32_t index, VkSemaphore rendered) {
  const VkSwapchainKHR presentTo = swapchain.swapchain;
  VkPresentInfoKHR info{VK_STRUCTURE_TYPE_PRESENT_INFO_KHR};
  info.waitSemaphoreCount = 1;
  info.pWaitSemaphores = &rendered;
  info.swapchainCount = 1;
  info.pSwapchains = &presentTo;
  info.pImageIndices = &index;
  const VkResult presented = vkQueuePresentKHR(gpu.queue, &info);
  const bool stale = presented == VK_ERROR_OUT_OF_DATE_KHR || presented == VK_SUBOPTIMAL_KHR;
  if (!stale) checkVk(presented, "vkQueuePresentKHR");
  return stale;
}

GlfwWindow::GlfwWindow(uint32_t width, uint32_t height, const std::string& title) {
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

GlfwWindow::~GlfwWindow() {
  glfwDestroyWindow(window_);
  glfwTerminate();
}

PictureShow::PictureShow(Gpu& gpu)
    : gpu_(gpu),
      cb_(allocateCommandBuffer(gpu)),
      copied_(createFence(gpu, false)),
      acquired_(createSemaphore(gpu)) {}

bool PictureShow::show(const Swapchain& swapchain,
                       const std::vector<Owned<VkSemaphore>>& rendered,
                       const std::vector<uint32_t>& rgba) {
  const VkDeviceSize bytes = rgba.size() * 4;
  if (staging_.size < bytes)
    staging_ = createBuffer(gpu_, bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, true);
  const bool bgra = swapchain.format == VK_FORMAT_B8G8R8A8_UNORM;
  const std::vector<uint32_t> words = toRgba(rgba, bgra);
  std::memcpy(staging_.mapped, words.data(), bytes);
  uint32_t index = 0;
  const VkResult acquire = vkAcquireNextImageKHR(gpu_.device, swapchain.swapchain.get(),
                                                 UINT64_MAX, acquired_.get(), VK_NULL_HANDLE,
                                                 &index);
  if (acquire == VK_ERROR_OUT_OF_DATE_KHR) return true;
  if (acquire != VK_SUCCESS && acquire != VK_SUBOPTIMAL_KHR)
    checkVk(acquire, "vkAcquireNextImageKHR");
  ISO_VK(vkResetCommandBuffer(cb_, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  ISO_VK(vkBeginCommandBuffer(cb_, &begin));
  recordCopyToSwapchain(cb_, staging_.buffer, swapchain.extent.width, swapchain.extent.height,
                        swapchain.images[index]);
  ISO_VK(vkEndCommandBuffer(cb_));
  const VkSemaphore wait = acquired_.get(), signal = rendered[index].get();
  const VkPipelineStageFlags stage = VK_PIPELINE_STAGE_TRANSFER_BIT;
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.waitSemaphoreCount = 1;
  submit.pWaitSemaphores = &wait;
  submit.pWaitDstStageMask = &stage;
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cb_;
  submit.signalSemaphoreCount = 1;
  submit.pSignalSemaphores = &signal;
  VkFence fence = copied_.get();
  ISO_VK(vkResetFences(gpu_.device, 1, &fence));
  ISO_VK(vkQueueSubmit(gpu_.queue, 1, &submit, fence));
  const bool stale = present(gpu_, swapchain, index, signal);
  // The staging buffer and the command buffer are the next picture's: wait for the copy.
  ISO_VK(vkWaitForFences(gpu_.device, 1, &fence, VK_TRUE, UINT64_MAX));
  return stale || acquire == VK_SUBOPTIMAL_KHR;
}

std::vector<uint32_t> enlarged(const std::vector<uint32_t>& pixels, uint32_t from, uint32_t width,
                               uint32_t height, uint32_t scale) {
  std::vector<uint32_t> out(size_t(width) * height);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x)
      out[size_t(y) * width + x] = pixels[size_t(y / scale) * from + x / scale];
  return out;
}

void saveScreenshots(Input& input, const ViewOptions& options, bool lastFrame, uint32_t width,
                     uint32_t height, const std::vector<uint32_t>& picture, uint32_t& taken) {
  const auto save = [&](const std::filesystem::path& file) {
    writeRgba8Image(file, width, height, picture);
    fmt::print("iso view: saved {}\n", file.string());
    std::fflush(stdout);  // a session watching the output sees it now
  };
  if (input.screenshot) save(fmt::format("iso-screenshot-{}.png", ++taken));
  input.screenshot = false;
  if (lastFrame && !options.screenshot.empty()) save(options.screenshot);
}

}  // namespace iso::viewer
