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

GpuPss::GpuPss(Gpu& gpu, const PssSurface& surface, const std::vector<glm::vec3>& colors)
    : gpu_(gpu), surface_(surface), colors_(!colors.empty()) {
  const size_t n = surface.size();
  std::vector<glm::vec4> positions(n), normals(n), rgb(colors_ ? n : 0), patches(4 * n);
  for (size_t i = 0; i < n; ++i) {
    positions[i] = glm::vec4(surface.positions()[i], surface.h()[i]);
    normals[i] = glm::vec4(surface.normals()[i], 0.0f);
    if (colors_) rgb[i] = glm::vec4(colors[i], 1.0f);
    const PssPatch& p = surface.patches()[i];
    patches[4 * i] = p.origin;
    patches[4 * i + 1] = p.normal;
    patches[4 * i + 2] = p.tangent;
    patches[4 * i + 3] = p.coefficients;
  }
  const PssSurface::Grid& grid = surface.grid();
  positions_ = upload(gpu, positions.data(), n);
  normals_ = upload(gpu, normals.data(), n);
  colorBuffer_ = upload(gpu, rgb.data(), rgb.size());
  patches_ = upload(gpu, patches.data(), patches.size());
  pointStart_ = upload(gpu, grid.pointStart.data(), grid.pointStart.size());
  points_ = upload(gpu, grid.points.data(), grid.points.size());
  reachStart_ = upload(gpu, grid.reachStart.data(), grid.reachStart.size());
  reach_ = upload(gpu, grid.reach.data(), grid.reach.size());
  params_ = createBuffer(gpu, sizeof(gpu::PssParams), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, true);
  const uint32_t none = 0;
  volumeStart_ = upload(gpu, &none, 1);
  volumeOrder_ = upload(gpu, &none, 1);
  volumePoints_ = upload(gpu, &none, 0);
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
  uint64_t sum = 0;
  for (const Buffer* b : {&params_, &positions_, &normals_, &colorBuffer_, &patches_,
                          &pointStart_, &points_, &reachStart_, &reach_, &pixels_, &volumeStart_,
                          &volumeOrder_, &volumePoints_})
    sum += b->allocated;
  return sum;
}

std::vector<uint32_t> GpuPss::render(const PssRender& r, double* gpuSeconds) {
  if (r.lights.size() > gpu::kPssMaxLights)
    throw UsageError("point set surfaces: at most " + std::to_string(gpu::kPssMaxLights) +
                     " lights");
  if (r.transfer.size() > gpu::kPssMaxTransfer)
    throw UsageError("a transfer function: at most " + std::to_string(gpu::kPssMaxTransfer) +
                     " points");
  if (r.volume && r.volume != volume_) {
    ISO_VK(vkDeviceWaitIdle(gpu_.device));
    volumeStart_ = upload(gpu_, r.volume->start().data(), r.volume->start().size());
    volumeOrder_ = upload(gpu_, r.volume->order().data(), r.volume->order().size());
    volumePoints_ = upload(gpu_, r.volume->points().data(), r.volume->points().size());
    volume_ = r.volume;
  }
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
  const PssSurface::Grid& grid = surface_.grid();
  q.gridLo = glm::vec4(grid.lo, grid.side);
  q.gridDims = glm::uvec4(glm::uvec3(grid.dims), uint32_t(r.lights.size()));
  q.image = glm::uvec4(uint32_t(r.width), uint32_t(r.height),
                       (r.exact ? gpu::kPssExact : 0u) | (r.shadows ? gpu::kPssShadows : 0u) |
                           (colors_ ? gpu::kPssColors : 0u),
                       0u);
  const PssOptions& o = surface_.options();
  q.settings = glm::vec4(o.trust, o.reach, o.tolerance, float(o.maxProjections));
  q.material = r.material;
  q.iors = glm::vec4(r.iors, r.ambient);
  q.color = glm::vec4(r.color, r.reflectivity);
  q.background = glm::vec4(r.background, 0.0f);
  for (size_t l = 0; l < r.lights.size(); ++l)
    q.lights[l] = glm::vec4(r.lights[l].position, r.lights[l].intensity);
  if (r.volume && !r.transfer.empty()) {
    q.volumeLo = glm::vec4(r.volume->lo(), r.volume->side());
    q.volumeDims = glm::uvec4(glm::uvec3(r.volume->dims()), uint32_t(r.transfer.size()));
    q.volumeSettings = glm::vec4(r.volume->smoothing(), r.volume->reach(), r.volume->step(), 0.0f);
    for (size_t k = 0; k < r.transfer.size(); ++k) {
      q.transfer[2 * k] = glm::vec4(r.transfer[k].value, r.transfer[k].extinction, 0.0f, 0.0f);
      q.transfer[2 * k + 1] = glm::vec4(r.transfer[k].color, 0.0f);
    }
  }
  std::memcpy(params_.mapped, &q, sizeof q);

  std::array<VkDescriptorBufferInfo, kBindings + 1> infos{};
  infos[0] = {params_.buffer, 0, sizeof q};
  const Buffer* storage[kBindings] = {&positions_,   &normals_,      &colorBuffer_,
                                      &patches_,     &pointStart_,   &points_,
                                      &reachStart_,  &reach_,        &pixels_,
                                      &volumeStart_, &volumeOrder_,  &volumePoints_};
  for (uint32_t b = 0; b < kBindings; ++b) infos[b + 1] = {storage[b]->buffer, 0, VK_WHOLE_SIZE};
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
