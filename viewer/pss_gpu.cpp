// Point set surfaces on the GPU (pss_gpu.h).
#include "viewer/pss_gpu.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>

#include "iso/error.h"
#include "shaders/shared.h"

namespace iso::viewer {
namespace {

const uint32_t kPssSpirv[] =
#include "pss.comp.spv.inc"
    ;

constexpr uint32_t kGroup = 64;  // invocations a workgroup (pss.comp.glsl)
constexpr uint32_t kBindings = 12;
constexpr VkBufferUsageFlags kStorage =
    VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;

template <typename T>
Buffer upload(Gpu& gpu, const T* data, size_t count) {
  const size_t bytes = count * sizeof(T);
  Buffer b = createBuffer(gpu, std::max<VkDeviceSize>(bytes, 16), kStorage, true);
  if (bytes > 0) std::memcpy(b.mapped, data, bytes);
  return b;
}

}  // namespace

PssBuffers::PssBuffers(Gpu& gpu, const PssSurface* surface, const std::vector<glm::vec3>& colors)
    : gpu_(gpu), surface_(surface), colors_(surface != nullptr && !colors.empty()) {
  const size_t n = surface ? surface->size() : 0;
  std::vector<glm::vec4> positions(n), normals(n), rgb(colors_ ? n : 0), patches(4 * n);
  for (size_t i = 0; i < n; ++i) {
    positions[i] = glm::vec4(surface->positions()[i], surface->h()[i]);
    normals[i] = glm::vec4(surface->normals()[i], 0.0f);
    if (colors_) rgb[i] = glm::vec4(colors[i], 1.0f);
    const PssPatch& p = surface->patches()[i];
    patches[4 * i] = p.origin;
    patches[4 * i + 1] = p.normal;
    patches[4 * i + 2] = p.tangent;
    patches[4 * i + 3] = p.coefficients;
  }
  const uint32_t none = 0;
  const auto list = [&](const std::vector<uint32_t>* v) {
    return v ? upload(gpu, v->data(), v->size()) : upload(gpu, &none, 1);
  };
  const PssSurface::Grid* grid = surface ? &surface->grid() : nullptr;
  positions_ = upload(gpu, positions.data(), n);
  normals_ = upload(gpu, normals.data(), n);
  colorBuffer_ = upload(gpu, rgb.data(), rgb.size());
  patches_ = upload(gpu, patches.data(), patches.size());
  pointStart_ = list(grid ? &grid->pointStart : nullptr);
  points_ = list(grid ? &grid->points : nullptr);
  reachStart_ = list(grid ? &grid->reachStart : nullptr);
  reach_ = list(grid ? &grid->reach : nullptr);
  setVolume(nullptr);
}

void PssBuffers::setVolume(const PssVolume* volume) {
  if (volume == volume_ && volumeStart_.buffer) return;
  if (volumeStart_.buffer) ISO_VK(vkDeviceWaitIdle(gpu_.device));
  const uint32_t none = 0;
  volumeStart_ = volume ? upload(gpu_, volume->start().data(), volume->start().size())
                        : upload(gpu_, &none, 1);
  volumeOrder_ = volume ? upload(gpu_, volume->order().data(), volume->order().size())
                        : upload(gpu_, &none, 1);
  volumePoints_ = volume ? upload(gpu_, volume->points().data(), volume->points().size())
                         : upload(gpu_, &none, 0);
  volume_ = volume;
}

std::array<const Buffer*, gpu::kPssStorageBindings> PssBuffers::storage() const {
  return {&positions_,  &normals_, &colorBuffer_, &patches_,     &pointStart_,  &points_,
          &reachStart_, &reach_,   &volumeStart_, &volumeOrder_, &volumePoints_};
}

void PssBuffers::fill(gpu::PssParams& q, const std::vector<PssTransferPoint>& transfer) const {
  fillPssParams(q, surface_, colors_, volume_, transfer);
}

uint64_t PssBuffers::memoryBytes() const {
  uint64_t sum = 0;
  for (const Buffer* b : storage()) sum += b->allocated;
  return sum;
}

GpuPss::GpuPss(Gpu& gpu, const PssSurface& surface, const std::vector<glm::vec3>& colors)
    : gpu_(gpu), surface_(surface), buffers_(gpu, &surface, colors) {
  params_ = createBuffer(gpu, sizeof(gpu::PssParams), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, true);
  std::array<uint32_t, kBindings> counts;
  counts.fill(1);
  const std::vector<std::vector<uint32_t>> variants = {{}};
  pipeline_ = createComputePipeline(gpu, kPssSpirv, counts, variants, 1);
  cb_ = allocateCommandBuffer(gpu);
  fence_ = createFence(gpu, false);
  if (gpu.timestampValidBits > 0) queries_ = createTimestampQueries(gpu, 2);
}

GpuPss::~GpuPss() {
  if (!gpu_.device) return;
  vkDeviceWaitIdle(gpu_.device);
  vkFreeCommandBuffers(gpu_.device, gpu_.commandPool, 1, &cb_);
}

uint64_t GpuPss::memoryBytes() const {
  return buffers_.memoryBytes() + params_.allocated + pixels_.allocated;
}

std::vector<uint32_t> GpuPss::render(const PssRender& r, double* gpuSeconds) {
  if (r.lights.size() > gpu::kPssMaxLights)
    throw UsageError("point set surfaces: at most " + std::to_string(gpu::kPssMaxLights) +
                     " lights");
  buffers_.setVolume(r.volume);
  const size_t pixels = size_t(r.width) * size_t(r.height);
  if (pixels_.size < pixels * 4) {
    ISO_VK(vkDeviceWaitIdle(gpu_.device));
    pixels_ = createBuffer(gpu_, pixels * 4, kStorage, true);
  }
  // The parameters, as renderPss frames its rays.
  gpu::PssParams q{};
  const PssRays rays = pssRays(r);
  q.eye = glm::vec4(r.eye, pssScale(surface_));
  q.right = glm::vec4(rays.right, 0.0f);
  q.up = glm::vec4(rays.up, 0.0f);
  q.forward = glm::vec4(rays.forward, 0.0f);
  q.gridDims.w = uint32_t(r.lights.size());
  q.image = glm::uvec4(uint32_t(r.width), uint32_t(r.height),
                       (r.exact ? gpu::kPssExact : 0u) | (r.shadows ? gpu::kPssShadows : 0u), 0u);
  buffers_.fill(q, r.volume ? r.transfer : std::vector<PssTransferPoint>{});
  q.material = r.material;
  q.iors = glm::vec4(r.iors, r.ambient);
  q.color = glm::vec4(r.color, r.reflectivity);
  q.background = glm::vec4(r.background, 0.0f);
  for (size_t l = 0; l < r.lights.size(); ++l)
    q.lights[l] = glm::vec4(r.lights[l].position, r.lights[l].intensity);
  std::memcpy(params_.mapped, &q, sizeof q);

  std::array<VkDescriptorBufferInfo, kBindings + 1> infos{};
  infos[0] = {params_.buffer, 0, sizeof q};
  const auto storage = buffers_.storage();
  for (uint32_t b = 0; b < gpu::kPssStorageBindings; ++b)
    infos[b + 1] = {storage[b]->buffer, 0, VK_WHOLE_SIZE};
  infos[kBindings] = {pixels_.buffer, 0, VK_WHOLE_SIZE};
  writeComputeSet(gpu_, pipeline_.sets[0], infos);

  ISO_VK(vkResetCommandBuffer(cb_, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  ISO_VK(vkBeginCommandBuffer(cb_, &begin));
  if (queries_) {
    vkCmdResetQueryPool(cb_, queries_.get(), 0, 2);
    vkCmdWriteTimestamp(cb_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries_.get(), 0);
  }
  vkCmdBindPipeline(cb_, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.pipelines[0]);
  vkCmdBindDescriptorSets(cb_, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.layout, 0, 1,
                          &pipeline_.sets[0], 0, nullptr);
  const uint64_t groups = (pixels + kGroup - 1) / kGroup;
  const uint32_t x = uint32_t(std::min<uint64_t>(groups, 65535));
  vkCmdDispatch(cb_, x, uint32_t((groups + x - 1) / x), 1);
  VkMemoryBarrier barrier{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  barrier.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  barrier.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  vkCmdPipelineBarrier(cb_, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0,
                       1, &barrier, 0, nullptr, 0, nullptr);
  if (queries_)
    vkCmdWriteTimestamp(cb_, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, queries_.get(), 1);
  ISO_VK(vkEndCommandBuffer(cb_));
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cb_;
  VkFence fence = fence_.get();
  ISO_VK(vkResetFences(gpu_.device, 1, &fence));
  ISO_VK(vkQueueSubmit(gpu_.queue, 1, &submit, fence));
  ISO_VK(vkWaitForFences(gpu_.device, 1, &fence, VK_TRUE, UINT64_MAX));
  if (gpuSeconds && queries_) {
    uint64_t stamps[2] = {0, 0};
    if (vkGetQueryPoolResults(gpu_.device, queries_.get(), 0, 2, sizeof stamps, stamps, 8,
                              VK_QUERY_RESULT_64_BIT) == VK_SUCCESS) {
      const uint64_t mask = gpu_.timestampValidBits >= 64
                                ? ~uint64_t(0)
                                : (uint64_t(1) << gpu_.timestampValidBits) - 1;
      *gpuSeconds = double((stamps[1] - stamps[0]) & mask) *
                    double(gpu_.properties.limits.timestampPeriod) * 1e-9;
    }
  }
  const auto* words = static_cast<const uint32_t*>(pixels_.mapped);
  return std::vector<uint32_t>(words, words + pixels);
}

}  // namespace iso::viewer
