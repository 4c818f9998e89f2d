// The viewer's Vulkan layer (vulkan.h).
#include "viewer/vulkan.h"

#include <fmt/core.h>
#include <cstdlib>
#include <cstring>

namespace iso::viewer {
namespace {

const char* resultName(VkResult r) {
  switch (r) {
    case VK_SUCCESS:
      return "VK_SUCCESS";
    case VK_NOT_READY:
      return "VK_NOT_READY";
    case VK_TIMEOUT:
      return "VK_TIMEOUT";
    case VK_INCOMPLETE:
      return "VK_INCOMPLETE";
    case VK_SUBOPTIMAL_KHR:
      return "VK_SUBOPTIMAL_KHR";
    case VK_ERROR_OUT_OF_HOST_MEMORY:
      return "VK_ERROR_OUT_OF_HOST_MEMORY";
    case VK_ERROR_OUT_OF_DEVICE_MEMORY:
      return "VK_ERROR_OUT_OF_DEVICE_MEMORY";
    case VK_ERROR_INITIALIZATION_FAILED:
      return "VK_ERROR_INITIALIZATION_FAILED";
    case VK_ERROR_DEVICE_LOST:
      return "VK_ERROR_DEVICE_LOST";
    case VK_ERROR_MEMORY_MAP_FAILED:
      return "VK_ERROR_MEMORY_MAP_FAILED";
    case VK_ERROR_LAYER_NOT_PRESENT:
      return "VK_ERROR_LAYER_NOT_PRESENT";
    case VK_ERROR_EXTENSION_NOT_PRESENT:
      return "VK_ERROR_EXTENSION_NOT_PRESENT";
    case VK_ERROR_FEATURE_NOT_PRESENT:
      return "VK_ERROR_FEATURE_NOT_PRESENT";
    case VK_ERROR_INCOMPATIBLE_DRIVER:
      return "VK_ERROR_INCOMPATIBLE_DRIVER (no Vulkan driver)";
    case VK_ERROR_TOO_MANY_OBJECTS:
      return "VK_ERROR_TOO_MANY_OBJECTS";
    case VK_ERROR_SURFACE_LOST_KHR:
      return "VK_ERROR_SURFACE_LOST_KHR";
    case VK_ERROR_OUT_OF_DATE_KHR:
      return "VK_ERROR_OUT_OF_DATE_KHR";
    default:
      return "VkResult";
  }
}

VKAPI_ATTR VkBool32 VKAPI_CALL onMessage(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                         VkDebugUtilsMessageTypeFlagsEXT,
                                         const VkDebugUtilsMessengerCallbackDataEXT* data,
                                         void* user) {
  if (severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
    fmt::print(stderr, "iso view: Vulkan {}: {}\n",
               severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT ? "error" : "warning",
               data->pMessage);
    if (severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT)
      static_cast<std::atomic<uint32_t>*>(user)->fetch_add(1);
  }
  return VK_FALSE;
}

bool hasLayer(const char* name) {
  uint32_t count = 0;
  vkEnumerateInstanceLayerProperties(&count, nullptr);
  std::vector<VkLayerProperties> layers(count);
  vkEnumerateInstanceLayerProperties(&count, layers.data());
  for (const auto& l : layers)
    if (std::strcmp(l.layerName, name) == 0) return true;
  return false;
}

int deviceRank(VkPhysicalDeviceType type) {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU:
      return 0;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU:
      return 1;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU:
      return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU:
      return 3;
    default:
      return 4;
  }
}

uint32_t memoryType(const Gpu& gpu, uint32_t typeBits, VkMemoryPropertyFlags wanted) {
  for (uint32_t i = 0; i < gpu.memory.memoryTypeCount; ++i)
    if ((typeBits & (1u << i)) && (gpu.memory.memoryTypes[i].propertyFlags & wanted) == wanted)
      return i;
  return UINT32_MAX;
}

}  // namespace

VulkanError::VulkanError(const std::string& call, VkResult result)
    : std::runtime_error(
          fmt::format("Vulkan: {} failed: {} ({})", call, resultName(result), int(result))),
      result_(result) {}

void checkVk(VkResult result, const char* call) {
  if (result != VK_SUCCESS) throw VulkanError(call, result);
}

std::string describeDevices(VkInstance instance) {
  uint32_t count = 0;
  vkEnumeratePhysicalDevices(instance, &count, nullptr);
  std::vector<VkPhysicalDevice> devices(count);
  vkEnumeratePhysicalDevices(instance, &count, devices.data());
  std::string out;
  for (VkPhysicalDevice d : devices) {
    VkPhysicalDeviceProperties p;
    vkGetPhysicalDeviceProperties(d, &p);
    out += (out.empty() ? "" : ", ") + std::string(p.deviceName);
  }
  return out.empty() ? "none" : out;
}

namespace {

// The physical device and its compute queue family: the first whose name holds `name` (or
// $ISO_VK_DEVICE), of the best kind (discrete, integrated, virtual, CPU), with Vulkan 1.2.
void choosePhysicalDevice(Gpu& gpu, const std::string& name) {
  uint32_t count = 0;
  ISO_VK(vkEnumeratePhysicalDevices(gpu.instance, &count, nullptr));
  std::vector<VkPhysicalDevice> devices(count);
  ISO_VK(vkEnumeratePhysicalDevices(gpu.instance, &count, devices.data()));
  const char* envName = std::getenv("ISO_VK_DEVICE");
  const std::string wanted = !name.empty() ? name : envName ? envName : "";
  int best = 1 << 30;
  for (VkPhysicalDevice d : devices) {
    VkPhysicalDeviceProperties p;
    vkGetPhysicalDeviceProperties(d, &p);
    if (p.apiVersion < VK_API_VERSION_1_2) continue;
    if (!wanted.empty() && std::string(p.deviceName).find(wanted) == std::string::npos) continue;
    uint32_t families = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(d, &families, nullptr);
    std::vector<VkQueueFamilyProperties> props(families);
    vkGetPhysicalDeviceQueueFamilyProperties(d, &families, props.data());
    for (uint32_t f = 0; f < families; ++f) {
      if (!(props[f].queueFlags & VK_QUEUE_COMPUTE_BIT)) continue;
      if (deviceRank(p.deviceType) < best) {
        best = deviceRank(p.deviceType);
        gpu.physical = d;
        gpu.queueFamily = f;
        gpu.timestampValidBits = props[f].timestampValidBits;
      }
      break;
    }
  }
  if (gpu.physical == VK_NULL_HANDLE)
    throw std::runtime_error(fmt::format(
        "no Vulkan 1.2 device with a compute queue{} (devices: {}); install "
        "mesa-vulkan-drivers for the CPU one",
        wanted.empty() ? "" : " named like '" + wanted + "'", describeDevices(gpu.instance)));
}

// The logical device with the features the tracer needs, and its queue.
void createDevice(Gpu& gpu, bool swapchain) {
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queueInfo{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queueInfo.queueFamilyIndex = gpu.queueFamily;
  queueInfo.queueCount = 1;
  queueInfo.pQueuePriorities = &priority;
  std::vector<const char*> deviceExtensions;
  if (swapchain) deviceExtensions.push_back(VK_KHR_SWAPCHAIN_EXTENSION_NAME);
  // The page pool is read through buffer device addresses (64-bit).
  VkPhysicalDeviceVulkan12Features has12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
  VkPhysicalDeviceFeatures2 has{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
  has.pNext = &has12;
  vkGetPhysicalDeviceFeatures2(gpu.physical, &has);
  if (!has12.bufferDeviceAddress || !has.features.shaderInt64)
    throw std::runtime_error(
        fmt::format("the Vulkan device {} lacks bufferDeviceAddress or "
                    "shaderInt64, which the viewer needs",
                    gpu.properties.deviceName));
  VkPhysicalDeviceVulkan12Features use12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
  use12.bufferDeviceAddress = VK_TRUE;
  // Image-space points project with 64-bit atomic minima (point_image_gpu.h), where offered.
  use12.shaderBufferInt64Atomics = has12.shaderBufferInt64Atomics;
  gpu.int64Atomics = has12.shaderBufferInt64Atomics == VK_TRUE;
  VkPhysicalDeviceFeatures2 use{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
  use.pNext = &use12;
  use.features.shaderInt64 = VK_TRUE;
  VkDeviceCreateInfo deviceInfo{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  deviceInfo.pNext = &use;
  deviceInfo.queueCreateInfoCount = 1;
  deviceInfo.pQueueCreateInfos = &queueInfo;
  deviceInfo.enabledExtensionCount = uint32_t(deviceExtensions.size());
  deviceInfo.ppEnabledExtensionNames = deviceExtensions.data();
  ISO_VK(vkCreateDevice(gpu.physical, &deviceInfo, nullptr, &gpu.device));
  vkGetDeviceQueue(gpu.device, gpu.queueFamily, 0, &gpu.queue);
}

}  // namespace

Gpu createGpu(const GpuOptions& options) {
  Gpu gpu;
  gpu.validationErrors = std::make_unique<std::atomic<uint32_t>>(0);
  const char* env = std::getenv("ISO_VK_VALIDATION");
  const bool validation = (options.validation || (env && std::string(env) == "1")) &&
                          hasLayer("VK_LAYER_KHRONOS_validation");
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "iso view";
  app.apiVersion = VK_API_VERSION_1_2;
  std::vector<const char*> extensions = options.instanceExtensions;
  std::vector<const char*> layers;
  if (validation) {
    extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
    layers.push_back("VK_LAYER_KHRONOS_validation");
  }
  VkInstanceCreateInfo instanceInfo{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  instanceInfo.pApplicationInfo = &app;
  instanceInfo.enabledExtensionCount = uint32_t(extensions.size());
  instanceInfo.ppEnabledExtensionNames = extensions.data();
  instanceInfo.enabledLayerCount = uint32_t(layers.size());
  instanceInfo.ppEnabledLayerNames = layers.data();
  // What is made below is destroyed by gpu's destructor if a later step throws.
  ISO_VK(vkCreateInstance(&instanceInfo, nullptr, &gpu.instance));
  if (validation) {
    VkDebugUtilsMessengerCreateInfoEXT m{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
    m.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                        VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    m.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                    VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                    VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    m.pfnUserCallback = onMessage;
    m.pUserData = gpu.validationErrors.get();
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(gpu.instance, "vkCreateDebugUtilsMessengerEXT"));
    if (create) ISO_VK(create(gpu.instance, &m, nullptr, &gpu.messenger));
  }
  choosePhysicalDevice(gpu, options.deviceName);
  vkGetPhysicalDeviceProperties(gpu.physical, &gpu.properties);
  vkGetPhysicalDeviceMemoryProperties(gpu.physical, &gpu.memory);
  createDevice(gpu, options.swapchain);
  VkCommandPoolCreateInfo poolInfo{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  poolInfo.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  poolInfo.queueFamilyIndex = gpu.queueFamily;
  ISO_VK(vkCreateCommandPool(gpu.device, &poolInfo, nullptr, &gpu.commandPool));
  return gpu;
}

Gpu::Gpu(Gpu&& o) noexcept
    : instance(std::exchange(o.instance, VK_NULL_HANDLE)),
      messenger(std::exchange(o.messenger, VK_NULL_HANDLE)),
      physical(o.physical),
      device(std::exchange(o.device, VK_NULL_HANDLE)),
      queue(o.queue),
      queueFamily(o.queueFamily),
      timestampValidBits(o.timestampValidBits),
      int64Atomics(o.int64Atomics),
      properties(o.properties),
      memory(o.memory),
      commandPool(std::exchange(o.commandPool, VK_NULL_HANDLE)),
      memoryInUse(o.memoryInUse),
      memoryPeak(o.memoryPeak),
      validationErrors(std::move(o.validationErrors)) {}

Gpu::~Gpu() {
  if (device) {
    vkDeviceWaitIdle(device);
    if (commandPool) vkDestroyCommandPool(device, commandPool, nullptr);
    vkDestroyDevice(device, nullptr);
  }
  if (messenger) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance, messenger, nullptr);
  }
  if (instance) vkDestroyInstance(instance, nullptr);
}

VkDeviceSize bufferFootprint(Gpu& gpu, VkDeviceSize size, VkBufferUsageFlags usage) {
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  VkBuffer buffer;
  ISO_VK(vkCreateBuffer(gpu.device, &info, nullptr, &buffer));
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(gpu.device, buffer, &req);
  vkDestroyBuffer(gpu.device, buffer, nullptr);
  return req.size;
}

Buffer createBuffer(Gpu& gpu, VkDeviceSize size, VkBufferUsageFlags usage, bool hostVisible) {
  Buffer b;  // destroyed if a step below throws
  b.gpu = &gpu;
  b.size = size;
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  ISO_VK(vkCreateBuffer(gpu.device, &info, nullptr, &b.buffer));
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(gpu.device, b.buffer, &req);
  const VkMemoryPropertyFlags wanted =
      hostVisible ? VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                  : VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
  uint32_t type = memoryType(gpu, req.memoryTypeBits, wanted);
  if (type == UINT32_MAX && !hostVisible) type = memoryType(gpu, req.memoryTypeBits, 0);
  if (type == UINT32_MAX) throw std::runtime_error("Vulkan: no memory type for a buffer");
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  VkMemoryAllocateFlagsInfo flags{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO};
  flags.flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT;
  if (usage & VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT) alloc.pNext = &flags;
  alloc.allocationSize = req.size;
  alloc.memoryTypeIndex = type;
  if (VkResult r = vkAllocateMemory(gpu.device, &alloc, nullptr, &b.memory); r != VK_SUCCESS)
    throw VulkanError(fmt::format("vkAllocateMemory({} bytes)", req.size), r);
  b.allocated = req.size;
  gpu.memoryInUse += req.size;
  gpu.memoryPeak = std::max(gpu.memoryPeak, gpu.memoryInUse);
  ISO_VK(vkBindBufferMemory(gpu.device, b.buffer, b.memory, 0));
  if (hostVisible) ISO_VK(vkMapMemory(gpu.device, b.memory, 0, VK_WHOLE_SIZE, 0, &b.mapped));
  if (usage & VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT) {
    VkBufferDeviceAddressInfo info{VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO};
    info.buffer = b.buffer;
    b.address = vkGetBufferDeviceAddress(gpu.device, &info);
  }
  return b;
}

Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    release();
    gpu = std::exchange(o.gpu, nullptr);
    buffer = std::exchange(o.buffer, VK_NULL_HANDLE);
    memory = std::exchange(o.memory, VK_NULL_HANDLE);
    size = std::exchange(o.size, 0);
    allocated = std::exchange(o.allocated, 0);
    mapped = std::exchange(o.mapped, nullptr);
    address = std::exchange(o.address, 0);
  }
  return *this;
}

void Buffer::release() {
  if (!gpu) return;
  if (buffer) vkDestroyBuffer(gpu->device, buffer, nullptr);
  if (memory) {
    vkFreeMemory(gpu->device, memory, nullptr);
    gpu->memoryInUse -= allocated;
  }
  gpu = nullptr;
  buffer = VK_NULL_HANDLE;
  memory = VK_NULL_HANDLE;
  size = allocated = 0;
  mapped = nullptr;
  address = 0;
}

void writeComputeSet(Gpu& gpu, VkDescriptorSet set, std::span<const VkDescriptorBufferInfo> infos) {
  std::vector<VkWriteDescriptorSet> writes(infos.size(), {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET});
  for (uint32_t i = 0; i < infos.size(); ++i) {
    writes[i].dstSet = set;
    writes[i].dstBinding = i;
    writes[i].descriptorCount = 1;
    writes[i].descriptorType =
        i == 0 ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &infos[i];
  }
  vkUpdateDescriptorSets(gpu.device, uint32_t(writes.size()), writes.data(), 0, nullptr);
}

ComputePipeline createComputePipeline(Gpu& gpu, std::span<const uint32_t> spirv,
                                      std::span<const uint32_t> storageCounts,
                                      std::span<const std::vector<uint32_t>> variants,
                                      uint32_t setCount) {
  ComputePipeline p;  // destroyed if a step below throws
  p.gpu = &gpu;
  std::vector<VkDescriptorSetLayoutBinding> bindings;
  bindings.push_back(
      {0, VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr});
  uint32_t storage = 0;
  for (size_t i = 0; i < storageCounts.size(); ++i) {
    bindings.push_back({uint32_t(i + 1), VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, storageCounts[i],
                        VK_SHADER_STAGE_COMPUTE_BIT, nullptr});
    storage += storageCounts[i];
  }
  VkDescriptorSetLayoutCreateInfo setInfo{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  setInfo.bindingCount = uint32_t(bindings.size());
  setInfo.pBindings = bindings.data();
  ISO_VK(vkCreateDescriptorSetLayout(gpu.device, &setInfo, nullptr, &p.setLayout));
  VkPipelineLayoutCreateInfo layoutInfo{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layoutInfo.setLayoutCount = 1;
  layoutInfo.pSetLayouts = &p.setLayout;
  ISO_VK(vkCreatePipelineLayout(gpu.device, &layoutInfo, nullptr, &p.layout));
  VkShaderModuleCreateInfo moduleInfo{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  moduleInfo.codeSize = spirv.size_bytes();
  moduleInfo.pCode = spirv.data();
  VkShaderModule module;
  ISO_VK(vkCreateShaderModule(gpu.device, &moduleInfo, nullptr, &module));
  VkResult made = VK_SUCCESS;
  for (const std::vector<uint32_t>& constants : variants) {
    VkComputePipelineCreateInfo info{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
    info.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
    info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    info.stage.module = module;
    info.stage.pName = "main";
    std::vector<VkSpecializationMapEntry> entries(constants.size());
    for (uint32_t i = 0; i < constants.size(); ++i) entries[i] = {i, 4 * i, 4};
    VkSpecializationInfo specialization{uint32_t(entries.size()), entries.data(),
                                        constants.size() * sizeof(uint32_t), constants.data()};
    if (!constants.empty()) info.stage.pSpecializationInfo = &specialization;
    info.layout = p.layout;
    VkPipeline pipeline = VK_NULL_HANDLE;
    made = vkCreateComputePipelines(gpu.device, VK_NULL_HANDLE, 1, &info, nullptr, &pipeline);
    if (made != VK_SUCCESS) break;
    p.pipelines.push_back(pipeline);
  }
  vkDestroyShaderModule(gpu.device, module, nullptr);
  ISO_VK(made);
  VkDescriptorPoolSize sizes[2] = {{VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, setCount},
                                   {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, storage * setCount}};
  VkDescriptorPoolCreateInfo poolInfo{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  poolInfo.maxSets = setCount;
  poolInfo.poolSizeCount = 2;
  poolInfo.pPoolSizes = sizes;
  ISO_VK(vkCreateDescriptorPool(gpu.device, &poolInfo, nullptr, &p.descriptorPool));
  VkDescriptorSetAllocateInfo alloc{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  alloc.descriptorPool = p.descriptorPool;
  const std::vector<VkDescriptorSetLayout> layouts(setCount, p.setLayout);
  alloc.descriptorSetCount = setCount;
  alloc.pSetLayouts = layouts.data();
  p.sets.resize(setCount);
  ISO_VK(vkAllocateDescriptorSets(gpu.device, &alloc, p.sets.data()));
  return p;
}

ComputePipeline& ComputePipeline::operator=(ComputePipeline&& o) noexcept {
  if (this != &o) {
    release();
    gpu = std::exchange(o.gpu, nullptr);
    setLayout = std::exchange(o.setLayout, VK_NULL_HANDLE);
    layout = std::exchange(o.layout, VK_NULL_HANDLE);
    pipelines = std::exchange(o.pipelines, {});
    descriptorPool = std::exchange(o.descriptorPool, VK_NULL_HANDLE);
    sets = std::exchange(o.sets, {});
  }
  return *this;
}

void ComputePipeline::release() {
  if (!gpu) return;
  VkDevice device = gpu->device;
  if (descriptorPool) vkDestroyDescriptorPool(device, descriptorPool, nullptr);
  for (VkPipeline pipeline : pipelines) vkDestroyPipeline(device, pipeline, nullptr);
  pipelines.clear();
  if (layout) vkDestroyPipelineLayout(device, layout, nullptr);
  if (setLayout) vkDestroyDescriptorSetLayout(device, setLayout, nullptr);
  gpu = nullptr;
  setLayout = VK_NULL_HANDLE;
  layout = VK_NULL_HANDLE;
  descriptorPool = VK_NULL_HANDLE;
  sets.clear();
}

VkCommandBuffer allocateCommandBuffer(Gpu& gpu) {
  VkCommandBufferAllocateInfo info{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  info.commandPool = gpu.commandPool;
  info.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  info.commandBufferCount = 1;
  VkCommandBuffer cb;
  ISO_VK(vkAllocateCommandBuffers(gpu.device, &info, &cb));
  return cb;
}

Owned<VkQueryPool> createTimestampQueries(Gpu& gpu, uint32_t count) {
  VkQueryPoolCreateInfo info{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
  info.queryType = VK_QUERY_TYPE_TIMESTAMP;
  info.queryCount = count;
  VkQueryPool pool;
  ISO_VK(vkCreateQueryPool(gpu.device, &info, nullptr, &pool));
  VkDevice device = gpu.device;
  return {pool, [device](VkQueryPool q) { vkDestroyQueryPool(device, q, nullptr); }};
}

Owned<VkFence> createFence(Gpu& gpu, bool signaled) {
  VkFenceCreateInfo info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  if (signaled) info.flags = VK_FENCE_CREATE_SIGNALED_BIT;
  VkFence fence;
  ISO_VK(vkCreateFence(gpu.device, &info, nullptr, &fence));
  VkDevice device = gpu.device;
  return {fence, [device](VkFence f) { vkDestroyFence(device, f, nullptr); }};
}

Owned<VkSemaphore> createSemaphore(Gpu& gpu) {
  VkSemaphoreCreateInfo info{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
  VkSemaphore semaphore;
  ISO_VK(vkCreateSemaphore(gpu.device, &info, nullptr, &semaphore));
  VkDevice device = gpu.device;
  return {semaphore, [device](VkSemaphore s) { vkDestroySemaphore(device, s, nullptr); }};
}

}  // namespace iso::viewer
