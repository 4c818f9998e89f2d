// A small Vulkan layer for the viewer: free functions over small structs that own what they
// hold (destroyed once, when they go; move-only), so that no caller writes a teardown. Every
// VkResult is checked; failures throw VulkanError naming the call and the result. Device memory
// is counted (Gpu::memoryInUse, Gpu::memoryPeak) so that the viewer can hold itself to --vram.
#pragma once

#include <vulkan/vulkan.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace iso::viewer {

class VulkanError : public std::runtime_error {
 public:
  VulkanError(const std::string& call, VkResult result);
  VkResult result() const { return result_; }

 private:
  VkResult result_;
};

void checkVk(VkResult result, const char* call);
#define ISO_VK(call) ::iso::viewer::checkVk((call), #call)

// One Vulkan object and the call that destroys it.
template <class Handle>
class Owned {
 public:
  Owned() = default;
  Owned(Handle handle, std::function<void(Handle)> destroy)
      : handle_(handle), destroy_(std::move(destroy)) {}
  Owned(Owned&& other) noexcept
      : handle_(std::exchange(other.handle_, Handle{})), destroy_(std::move(other.destroy_)) {}
  Owned& operator=(Owned&& other) noexcept {
    if (this != &other) {
      reset();
      handle_ = std::exchange(other.handle_, Handle{});
      destroy_ = std::move(other.destroy_);
    }
    return *this;
  }
  Owned(const Owned&) = delete;
  Owned& operator=(const Owned&) = delete;
  ~Owned() { reset(); }
  operator Handle() const { return handle_; }
  Handle get() const { return handle_; }
  void reset() {
    if (handle_ && destroy_) destroy_(handle_);
    handle_ = Handle{};
  }

 private:
  Handle handle_{};
  std::function<void(Handle)> destroy_;
};

struct GpuOptions {
  std::vector<const char*> instanceExtensions;  // e.g. what GLFW needs for a window surface
  bool swapchain = false;                       // enable VK_KHR_swapchain on the device
  bool validation = false;  // Khronos validation layer (also: ISO_VK_VALIDATION=1)
  std::string deviceName;   // a substring of the device to use (also: ISO_VK_DEVICE)
};

// The instance, device, queue and command pool; destroyed (after the device is idle) when it
// goes. Everything made from it must go first.
struct Gpu {
  Gpu() = default;
  Gpu(Gpu&& other) noexcept;
  Gpu& operator=(Gpu&&) = delete;
  ~Gpu();
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t queueFamily = 0;
  uint32_t timestampValidBits = 0;  // of the queue family; 0: no timestamps
  bool int64Atomics = false;        // shaderBufferInt64Atomics is on
  VkPhysicalDeviceProperties properties{};
  VkPhysicalDeviceMemoryProperties memory{};
  VkCommandPool commandPool = VK_NULL_HANDLE;
  uint64_t memoryInUse = 0;  // bytes of device memory allocated now
  uint64_t memoryPeak = 0;   // the most at once
  // Messages of severity error (at a fixed address: the messenger's callback counts them).
  std::unique_ptr<std::atomic<uint32_t>> validationErrors;
};

Gpu createGpu(const GpuOptions& options);
// Devices Vulkan offers here, for messages.
std::string describeDevices(VkInstance instance);

struct Buffer {
  Buffer() = default;
  Buffer(Buffer&& other) noexcept { *this = std::move(other); }
  Buffer& operator=(Buffer&& other) noexcept;
  ~Buffer() { release(); }
  void release();      // destroy it now (it becomes empty)
  Gpu* gpu = nullptr;  // its device, and the memory count it is charged to
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkDeviceSize size = 0;        // as asked
  VkDeviceSize allocated = 0;   // device memory it holds
  void* mapped = nullptr;       // host-visible buffers stay mapped
  VkDeviceAddress address = 0;  // with VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT
};

// A buffer in device-local memory, or host-visible coherent memory when hostVisible.
Buffer createBuffer(Gpu& gpu, VkDeviceSize size, VkBufferUsageFlags usage, bool hostVisible);
// Device memory a buffer of this size and usage would take (for budgets, before creating it).
VkDeviceSize bufferFootprint(Gpu& gpu, VkDeviceSize size, VkBufferUsageFlags usage);

struct ComputePipeline {
  ComputePipeline() = default;
  ComputePipeline(ComputePipeline&& other) noexcept { *this = std::move(other); }
  ComputePipeline& operator=(ComputePipeline&& other) noexcept;
  ~ComputePipeline() { release(); }
  void release();
  Gpu* gpu = nullptr;
  VkDescriptorSetLayout setLayout = VK_NULL_HANDLE;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  std::vector<VkPipeline> pipelines;  // one a variant, all of the one layout
  VkDescriptorPool descriptorPool = VK_NULL_HANDLE;
  std::vector<VkDescriptorSet> sets;  // of the one layout (a set a frame in flight)
};

// Compute pipelines of one shader whose descriptor set layout has a uniform buffer at binding 0
// and storage buffers at bindings 1 to storageBindings (each binding an array of `counts[i]`
// buffers), one a variant of the 32-bit specialization constants (constant_id i is variant[i]),
// and `setCount` descriptor sets of that layout.
ComputePipeline createComputePipeline(Gpu& gpu, std::span<const uint32_t> spirv,
                                      std::span<const uint32_t> storageCounts,
                                      std::span<const std::vector<uint32_t>> variants,
                                      uint32_t setCount = 1);

// Points a set of such a pipeline's layout at buffers: infos[0] the uniform buffer (binding 0),
// then one storage buffer a binding.
void writeComputeSet(Gpu& gpu, VkDescriptorSet set, std::span<const VkDescriptorBufferInfo> infos);

// From the Gpu's command pool (freed with it, or by vkFreeCommandBuffers).
VkCommandBuffer allocateCommandBuffer(Gpu& gpu);
// A pool of `count` timestamp queries.
Owned<VkQueryPool> createTimestampQueries(Gpu& gpu, uint32_t count);
Owned<VkFence> createFence(Gpu& gpu, bool signaled);
Owned<VkSemaphore> createSemaphore(Gpu& gpu);

}  // namespace iso::viewer
