// Image-space point rendering on the GPU (point_image_gpu.h).
#include "viewer/point_image_gpu.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "iso/error.h"
#include "shaders/shared.h"

namespace iso::viewer {
namespace {

const uint32_t kImageSpirv[] =
#include "image.comp.spv.inc"
    ;

using gpu::ImageParams;

constexpr uint32_t kGroup = 64;           // invocations a workgroup (image.comp.glsl)
constexpr uint32_t kMaxSamples = 64;      // samples of an area light at most
constexpr uint32_t kSlots = 2 + gpu::kMaxLights * kMaxSamples;  // eye, eye peeled, samples
// A descriptor set a slot and a side: side 0 binds layer buffers A and B as layers A and B, side
// 1 the other way round. Filling passes alternate sides (ping-pong), so no pass copies a layer.
constexpr uint32_t kSets = 2 * kSlots;
constexpr VkDeviceSize kParamsStride = 512;
constexpr uint32_t kStatsWord = 16;       // control words: per layer the passes of each kind
constexpr uint32_t kMaxLayers = 64;
constexpr uint32_t kMaxStamps = 4096;  // timestamps a frame: one after each step

static_assert(gpu::kImageFillTile >= gpu::kImageMaxFillRadius,
              "a changed pixel wakes only the tiles next to its own");
static_assert(gpu::kImageControlTiles + 4 <= kStatsWord, "control words before the statistics");

// The pipelines: a stage, and for filling and control a kind.
enum Variant : uint32_t {
  kProject,
  kFillBackground,
  kFillOccluded,
  kControlBackground,
  kControlOccluded,
  kControlStart,
  kControlShading,
  kShade,
  kSmooth,
  kLit,
  kVariants
};
constexpr std::array<ImageStep, kVariants> kVariantSteps = {
    ImageStep::Project, ImageStep::Fill,      ImageStep::Fill,
    ImageStep::Control, ImageStep::Control, ImageStep::Control,   ImageStep::Control,
    ImageStep::Shade,   ImageStep::Smooth,  ImageStep::Lit};
constexpr std::array<std::array<uint32_t, 2>, kVariants> kVariantConstants = {{
    {gpu::kImageStageProject, 0},
    {gpu::kImageStageFill, 0},
    {gpu::kImageStageFill, 1},
    {gpu::kImageStageControl, 0},
    {gpu::kImageStageControl, 1},
    {gpu::kImageStageControl, 2},
    {gpu::kImageStageControl, 3},
    {gpu::kImageStageShade, 0},
    {gpu::kImageStageSmooth, 0},
    {gpu::kImageStageLit, 0},
}};

constexpr VkBufferUsageFlags kStorage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT |
                                        VK_BUFFER_USAGE_TRANSFER_DST_BIT |
                                        VK_BUFFER_USAGE_TRANSFER_SRC_BIT;

// Workgroups for `count` invocations, rows of at most 65,535 (the shader continues on rows).
std::array<uint32_t, 3> groups(uint64_t count) {
  const uint64_t n = std::max<uint64_t>((count + kGroup - 1) / kGroup, 1);
  const uint32_t x = uint32_t(std::min<uint64_t>(n, 65535));
  return {x, uint32_t((n + x - 1) / x), 1};
}

// What the commands before wrote (shaders, transfers) made visible to what follows (shaders,
// indirect dispatches, transfers).
void barrier(VkCommandBuffer cb) {
  VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  b.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT |
                    VK_ACCESS_INDIRECT_COMMAND_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT |
                    VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_READ_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT |
                           VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT,
                       0, 1, &b, 0, nullptr, 0, nullptr);
}

Buffer upload(Gpu& gpu, const std::vector<glm::vec4>& data) {
  Buffer b = createBuffer(gpu, std::max<VkDeviceSize>(data.size() * sizeof(glm::vec4), 16),
                          kStorage, true);
  if (!data.empty()) std::memcpy(b.mapped, data.data(), data.size() * sizeof(glm::vec4));
  return b;
}

}  // namespace

GpuPointImage::GpuPointImage(Gpu& gpu, const PointImageScene& scene) : gpu_(gpu), scene_(&scene) {
  if (!gpu.int64Atomics)
    throw UsageError(std::string("image-space points need 64-bit buffer atomics, which ") +
                     gpu.properties.deviceName + " lacks: draw them with --cpu");
  std::vector<std::vector<uint32_t>> variants;
  for (const auto& c : kVariantConstants) variants.push_back({c[0], c[1]});
  const std::array<uint32_t, 14> counts = {1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1};
  pipeline_ = createComputePipeline(gpu, kImageSpirv, counts, variants, kSets);
  setScene(scene);
  params_ = createBuffer(gpu, kParamsStride * kSlots, VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, true);
  control_ = createBuffer(gpu, (kStatsWord + 2 * kMaxLayers) * 4,
                         kStorage | VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT, true);
  cb_ = allocateCommandBuffer(gpu);
  fence_ = createFence(gpu, false);
  if (gpu.timestampValidBits > 0) queries_ = createTimestampQueries(gpu, kMaxStamps);
}

void GpuPointImage::setScene(const PointImageScene& scene) {
  if (gpu_.device) ISO_VK(vkDeviceWaitIdle(gpu_.device));
  scene_ = &scene;
  positions_ = upload(gpu_, scene.positions());
  normals_ = upload(gpu_, scene.normals());
  colors_ = upload(gpu_, scene.colors());
  pointsChanged_ = true;
  shadowKey_.clear();
}

GpuPointImage::~GpuPointImage() {
  if (!gpu_.device) return;
  vkDeviceWaitIdle(gpu_.device);
  vkFreeCommandBuffers(gpu_.device, gpu_.commandPool, 1, &cb_);
}

ImageBudget imageBudget(uint64_t vram, uint64_t points, uint32_t width, uint32_t height,
                        size_t lights) {
  const uint64_t picture =
      uint64_t(width) * height * (kImageLayerPixelBytes + kImagePicturePixelBytes) + (16u << 20);
  const uint64_t left = vram > picture ? vram - picture : 0;
  const uint64_t perPoint = kImagePointBytes + kImageLitBytes * std::max<size_t>(lights, 1);
  ImageBudget b;
  b.points = std::min(points, left / 4 * 3 / perPoint);
  const double shadowBytes = double(left - b.points * perPoint);
  b.shadowResolution =
      int(std::clamp(std::sqrt(shadowBytes / kImageLayerPixelBytes), 256.0, 4096.0));
  return b;
}

uint64_t GpuPointImage::memoryBytes() const {
  uint64_t sum = 0;
  for (const Buffer* b : {&positions_, &normals_, &colors_, &params_, &layerA_, &layerB_,
                          &layerR_, &colorA_, &blended_, &lit_, &control_, &pixels_,
                          &tiles_})
    sum += b->allocated;
  return sum;
}

void GpuPointImage::prepare(const ImagePlan& plan, size_t lights) {
  size_t pixels = size_t(plan.eye.image.x) * plan.eye.image.y;
  for (const ImageParams& q : plan.samples) pixels = std::max(pixels, size_t(q.image.x) * q.image.y);
  const auto tilesOf = [](const ImageParams& q) {
    const size_t t = gpu::kImageFillTile;
    return (size_t(q.image.x) + t - 1) / t * ((size_t(q.image.y) + t - 1) / t);
  };
  size_t tiles = tilesOf(plan.eye);
  for (const ImageParams& q : plan.samples) tiles = std::max(tiles, tilesOf(q));
  const size_t eyePixels = size_t(plan.eye.image.x) * plan.eye.image.y;
  const size_t litWords = std::max<size_t>(scene_->size() * lights, 1);
  bool changed = pointsChanged_;
  pointsChanged_ = false;
  if (pixels > pixelCapacity_) {
    layerA_ = createBuffer(gpu_, pixels * 8, kStorage, false);
    layerB_ = createBuffer(gpu_, pixels * 8, kStorage, false);
    layerR_ = createBuffer(gpu_, pixels * 8, kStorage, false);
    pixelCapacity_ = pixels;
    changed = true;
  }
  if (eyePixels != eyePixels_) {
    colorA_ = createBuffer(gpu_, eyePixels * 16, kStorage, false);
    blended_ = createBuffer(gpu_, eyePixels * 16, kStorage, false);
    pixels_ = createBuffer(gpu_, eyePixels * 4, kStorage, true);
    eyePixels_ = eyePixels;
    changed = true;
  }
  if (tiles > tileCapacity_) {
    tiles_ = createBuffer(gpu_, tiles * 7 * 4, kStorage, false);
    tileCapacity_ = tiles;
    changed = true;
  }
  if (litWords > litCapacity_) {
    lit_ = createBuffer(gpu_, litWords * 4, kStorage, false);
    litCapacity_ = litWords;
    shadowKey_.clear();
    changed = true;
  }
  if (!changed && sets_ == kSets) return;
  std::vector<VkDescriptorBufferInfo> infos;
  infos.reserve(kSets * 15);
  std::vector<VkWriteDescriptorSet> writes;
  for (uint32_t set = 0; set < kSets; ++set) {
    const uint32_t slot = set / 2, side = set % 2;
    // Binding 4, the keys, is layer A's buffer (shaders/image.comp.glsl).
    const Buffer* storage[] = {&positions_, &normals_, &colors_, side == 0 ? &layerA_ : &layerB_,
                               side == 0 ? &layerA_ : &layerB_, side == 0 ? &layerB_ : &layerA_,
                               &layerR_,    &colorA_,  &colorA_, &blended_,
                               &lit_,       &control_, &pixels_, &tiles_};
    infos.push_back({params_.buffer, slot * kParamsStride, sizeof(ImageParams)});
    for (const Buffer* b : storage) infos.push_back({b->buffer, 0, VK_WHOLE_SIZE});
    for (uint32_t binding = 0; binding < 15; ++binding) {
      VkWriteDescriptorSet w{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
      w.dstSet = pipeline_.sets[set];
      w.dstBinding = binding;
      w.descriptorCount = 1;
      w.descriptorType =
          binding == 0 ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
      w.pBufferInfo = &infos[set * 15 + binding];
      writes.push_back(w);
    }
  }
  vkUpdateDescriptorSets(gpu_.device, uint32_t(writes.size()), writes.data(), 0, nullptr);
  sets_ = kSets;
}

GpuImageFrame GpuPointImage::render(const ImageCamera& camera, std::span<const ImageLight> lights,
                                    const ImageSettings& settings) {
  const ImagePlan plan = planImage(*scene_, camera, lights, settings);
  if (plan.samples.size() > kSlots - 2)
    throw UsageError("image-space shadows: at most " + std::to_string(kMaxSamples) +
                     " samples a light");
  if (plan.layers > int(kMaxLayers))
    throw UsageError("image-space points: at most " + std::to_string(kMaxLayers) + " layers");
  prepare(plan, lights.size());

  // The parameters: set 0 the eye's first layer, 1 its later layers, 2 + s the light samples.
  auto* params = static_cast<std::byte*>(params_.mapped);
  ImageParams first = plan.eye;
  if (plan.layers == 1) first.image.w |= gpu::kImageOnlyLayer;
  ImageParams peeled = plan.eye;
  peeled.image.w |= gpu::kImagePeel;
  std::memcpy(params, &first, sizeof(ImageParams));
  std::memcpy(params + kParamsStride, &peeled, sizeof(ImageParams));
  for (size_t s = 0; s < plan.samples.size(); ++s)
    std::memcpy(params + (2 + s) * kParamsStride, &plan.samples[s], sizeof(ImageParams));

  std::vector<float> key;
  for (const ImageParams& q : plan.samples) {
    const float* words = &q.eye.x;
    key.insert(key.end(), words, words + sizeof(ImageParams) / sizeof(float));
  }
  GpuImageFrame frame;
  const bool shadows = plan.shadows && (!plan.reuseShadows || key != shadowKey_);
  frame.stats.shadowsReused = plan.shadows && !shadows;

  VkCommandBuffer cb = cb_;
  ISO_VK(vkResetCommandBuffer(cb, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  ISO_VK(vkBeginCommandBuffer(cb, &begin));
  // A timestamp after each step, named by the step (ImageStep): the time from the one before
  // is that step's. A stamp at the start of each submit measures the wait before it.
  std::vector<ImageStep> stamps;
  auto stamp = [&](ImageStep step, VkPipelineStageFlagBits where) {
    if (!queries_ || stamps.size() >= kMaxStamps) return;
    vkCmdWriteTimestamp(cb, where, queries_.get(), uint32_t(stamps.size()));
    stamps.push_back(step);
  };
  if (queries_) vkCmdResetQueryPool(cb, queries_.get(), 0, kMaxStamps);
  stamp(ImageStep::Wait, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT);
  const VkPipelineLayout layout = pipeline_.layout;
  // The side whose layer A holds the layer now (filling passes flip it).
  uint32_t side = 0;
  auto dispatch = [&](Variant v, uint32_t slot, uint64_t count) {
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.pipelines[v]);
    vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, layout, 0, 1,
                            &pipeline_.sets[2 * slot + side], 0, nullptr);
    const auto g = groups(count);
    vkCmdDispatch(cb, g[0], g[1], g[2]);
    barrier(cb);
    stamp(kVariantSteps[v], VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT);
  };
  auto indirect = [&](Variant v, uint32_t slot) {
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.pipelines[v]);
    vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, layout, 0, 1,
                            &pipeline_.sets[2 * slot + side], 0, nullptr);
    vkCmdDispatchIndirect(cb, control_.buffer, 0);
    barrier(cb);
    stamp(kVariantSteps[v], VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT);
  };
  const uint64_t n = scene_->size();
  // Projection into layer A, cleared.
  // The tiles of slot `set`'s image (kImageFillTile pixels square).
  auto tilesOf = [&](uint32_t set) {
    const ImageParams& q = set < 2 ? plan.eye : plan.samples[set - 2];
    const uint64_t t = gpu::kImageFillTile;
    return (q.image.x + t - 1) / t * ((q.image.y + t - 1) / t);
  };
  auto project = [&](uint32_t set, uint64_t pixels) {
    // Layer A (this side's) holds the keys: none yet.
    vkCmdFillBuffer(cb, (side == 0 ? layerA_ : layerB_).buffer, 0, pixels * 8, 0xFFFFFFFFu);
    // No tile marked (arrays 0, 1 and the shading's), none listed for round 0 or shading.
    const uint64_t t = tilesOf(set);
    vkCmdFillBuffer(cb, tiles_.buffer, 0, t * 2 * 4, 0xFFFFFFFFu);
    vkCmdFillBuffer(cb, tiles_.buffer, t * 6 * 4, t * 4, 0xFFFFFFFFu);
    const uint32_t none[2] = {0, 0};
    vkCmdUpdateBuffer(cb, control_.buffer, (gpu::kImageControlTiles + 2) * 4, sizeof none, none);
    barrier(cb);
    stamp(ImageStep::Clear, VK_PIPELINE_STAGE_TRANSFER_BIT);
    dispatch(kProject, set, n);
  };
  // Filling passes of one kind until one changes nothing (its indirect dispatch then empties
  // the rest), at most plan.fillPasses.
  // The commands so far submitted and waited for; recording goes on in the same buffer.
  VkFence fence = fence_.get();
  auto submitAndWait = [&] {
    ISO_VK(vkEndCommandBuffer(cb));
    VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
    submit.commandBufferCount = 1;
    submit.pCommandBuffers = &cb;
    ISO_VK(vkResetFences(gpu_.device, 1, &fence));
    ISO_VK(vkQueueSubmit(gpu_.queue, 1, &submit, fence));
    ISO_VK(vkWaitForFences(gpu_.device, 1, &fence, VK_TRUE, UINT64_MAX));
    ++frame.submits;
  };
  auto flush = [&] {
    submitAndWait();
    ISO_VK(vkResetCommandBuffer(cb, 0));
    ISO_VK(vkBeginCommandBuffer(cb, &begin));
    stamp(ImageStep::Wait, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT);
  };
  // Rounds of filling (a pass, and the control that empties the next rounds' dispatches once one
  // changed nothing) submitted a few at a time, until one changes nothing
  // or plan.fillPasses ran: empty dispatches cost lavapipe about a millisecond each, and filling
  // takes a few passes.
  const auto* control = static_cast<const uint32_t*>(control_.mapped);
  auto fill = [&](uint32_t set, uint32_t kind) {
    // Round 0 over the tiles projection listed, no tile marked for later rounds.
    vkCmdFillBuffer(cb, tiles_.buffer, 0, tilesOf(set) * 2 * 4, 0xFFFFFFFFu);
    barrier(cb);
    dispatch(kControlStart, set, 1);
    const int rounds = kind == 0 ? plan.fillPasses : plan.occludedPasses;
    for (int round = 0; round < rounds;) {
      for (int k = 0; k < roundsPerSubmit_ && round < rounds; ++k, ++round) {
        // The pass reads this side's layer A and writes its layer B, the other side's A. A pass
        // that is skipped follows one that changed nothing, after which both hold the layer.
        indirect(kind == 0 ? kFillBackground : kFillOccluded, set);
        side ^= 1u;
        dispatch(kind == 0 ? kControlBackground : kControlOccluded, set, 1);
      }
      flush();
      if (control[0] == 0) break;  // a round changed nothing
    }
  };

  if (shadows) {
    vkCmdFillBuffer(cb, lit_.buffer, 0, VK_WHOLE_SIZE, 0);
    barrier(cb);
    for (size_t s = 0; s < plan.samples.size(); ++s) {
      const uint32_t set = uint32_t(2 + s);
      const uint64_t pixels = uint64_t(plan.samples[s].image.x) * plan.samples[s].image.y;
      project(set, pixels);
      fill(set, 1);  // occluded pixels only (point_image.cpp, computeShadows)
      dispatch(kLit, set, n);
      frame.stats.projected += 2 * n;
    }
  }
  const uint64_t pixels = eyePixels_;
  // Blending's sum and the layer kept for the next: only for several layers.
  if (plan.layers > 1) vkCmdFillBuffer(cb, blended_.buffer, 0, VK_WHOLE_SIZE, 0);
  // The picture: the background, where anti-aliasing writes no pixel.
  vkCmdFillBuffer(cb, pixels_.buffer, 0, VK_WHOLE_SIZE, imagePixelWord(settings.background));
  for (int k = 0; k < plan.layers; ++k) {
    const uint32_t set = k == 0 ? 0 : 1;
    const uint32_t zero[2] = {0, 0};
    vkCmdUpdateBuffer(cb, control_.buffer, gpu::kImageControlPasses * 4, sizeof zero, zero);
    project(set, pixels);
    fill(set, 0);
    fill(set, 1);
    VkBufferCopy copy{gpu::kImageControlPasses * 4, (kStatsWord + 2 * uint64_t(k)) * 4, 8};
    vkCmdCopyBuffer(cb, control_.buffer, control_.buffer, 1, &copy);
    // Shading over the tiles any filling round listed (every covered pixel's and those around).
    dispatch(kControlShading, set, 1);
    indirect(kShade, set);
    if (plan.layers > 1) {
      vkCmdFillBuffer(cb, layerR_.buffer, 0, pixels * 8, 0);  // blending keeps the layer as R
      barrier(cb);
    }
    indirect(kSmooth, set);  // smoothing, anti-aliasing and blending
    frame.stats.projected += n;
  }
  submitAndWait();
  if (shadows) shadowKey_ = std::move(key);

  const auto* words = static_cast<const uint32_t*>(pixels_.mapped);
  frame.pixels.assign(words, words + pixels);
  for (int k = 0; k < plan.layers; ++k) {
    frame.stats.backgroundPasses.push_back(int(control[kStatsWord + 2 * k]));
    frame.stats.occludedPasses.push_back(int(control[kStatsWord + 2 * k + 1]));
  }
  frame.stats.layers = plan.layers;
  if (queries_ && stamps.size() > 1) {
    std::vector<uint64_t> t(stamps.size());
    if (vkGetQueryPoolResults(gpu_.device, queries_.get(), 0, uint32_t(t.size()),
                              t.size() * 8, t.data(), 8, VK_QUERY_RESULT_64_BIT) == VK_SUCCESS) {
      const uint64_t mask = gpu_.timestampValidBits >= 64
                                ? ~uint64_t(0)
                                : (uint64_t(1) << gpu_.timestampValidBits) - 1;
      const double tick = double(gpu_.properties.limits.timestampPeriod) * 1e-9;
      for (size_t i = 1; i < t.size(); ++i) {
        const double seconds = double((t[i] - t[i - 1]) & mask) * tick;
        frame.stepSeconds[size_t(stamps[i])] += seconds;
        if (stamps[i] != ImageStep::Wait) frame.gpuSeconds += seconds;
      }
    }
  }
  return frame;
}

}  // namespace iso::viewer
