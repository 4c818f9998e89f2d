// A small Vulkan layer for the viewer: free functions over plain structs. Every VkResult is
// checked; failures throw VulkanError naming the call and the result. Device memory is counted
// (Gpu::memoryInUse, Gpu::memoryPeak) so that the viewer can hold itself to --vram.
#pragma once

#include <vulkan/vulkan.h>

#include <atomic>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
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

struct GpuOptions {
  std::vector<const char*> instanceExtensions;  // e.g. what GLFW needs for a window surface
  bool swapchain = false;                       // enable VK_KHR_swapchain on the device
  bool validation = false;  // Khronos validation layer (also: ISO_VK_VALIDATION=1)
  std::string deviceName;   // a substring of the device to use (also: ISO_VK_DEVICE)
};

struct Gpu {
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t queueFamily = 0;
  VkPhysicalDeviceProperties properties{};
  VkPhysicalDeviceMemoryProperties memory{};
  VkCommandPool commandPool = VK_NULL_HANDLE;
  uint64_t memoryInUse = 0;                           // bytes of device memory allocated now
  uint64_t memoryPeak = 0;                            // the most at once
  std::atomic<uint32_t>* validationErrors = nullptr;  // messages of severity error
};

Gpu createGpu(const GpuOptions& options);
void destroyGpu(Gpu& gpu);
// Devices Vulkan offers here, for messages.
std::string describeDevices(VkInstance instance);

struct Buffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkDeviceSize size = 0;        // as asked
  VkDeviceSize allocated = 0;   // device memory it holds
  void* mapped = nullptr;       // host-visible buffers stay mapped
  VkDeviceAddress address = 0;  // with VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT
};

// A buffer in device-local memory, or host-visible coherent memory when hostVisible.
Buffer createBuffer(Gpu& gpu, VkDeviceSize size, VkBufferUsageFlags usage, bool hostVisible);
void destroyBuffer(Gpu& gpu, Buffer& buffer);
// Device memory a buffer of this size and usage would take (for budgets, before creating it).
VkDeviceSize bufferFootprint(Gpu& gpu, VkDeviceSize size, VkBufferUsageFlags usage);

struct ComputePipeline {
  VkDescriptorSetLayout setLayout = VK_NULL_HANDLE;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VkPipeline pipeline = VK_NULL_HANDLE;
  VkDescriptorPool descriptorPool = VK_NULL_HANDLE;
  VkDescriptorSet set = VK_NULL_HANDLE;
};

// A compute pipeline whose one descriptor set has a uniform buffer at binding 0 and storage
// buffers at bindings 1 to storageBindings (each binding an array of `counts[i]` buffers), with
// the 32-bit specialization constants `constants` (constant_id i is constants[i]).
ComputePipeline createComputePipeline(Gpu& gpu, std::span<const uint32_t> spirv,
                                      std::span<const uint32_t> storageCounts,
                                      std::span<const uint32_t> constants = {});
void destroyComputePipeline(Gpu& gpu, ComputePipeline& pipeline);

VkCommandBuffer allocateCommandBuffer(Gpu& gpu);
VkFence createFence(Gpu& gpu, bool signaled);

}  // namespace iso::viewer
