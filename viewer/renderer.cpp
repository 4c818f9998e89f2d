// The viewer's GPU frames and streaming uploads (renderer.h).
#include "viewer/renderer.h"

#include <fmt/core.h>
#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>

#include "iso/check.h"

namespace iso::viewer {
namespace {

const uint32_t kTraceSpirv[] =
#include "trace.comp.spv.inc"
    ;

constexpr uint64_t kPageBytes = uint64_t(gpu::kPageWords) * 4;

// An upper bound of a chunk's blob size from its table entry (buildBlob's layout): node records,
// a record per node, and at most a link list (16 words) per internal node.
uint64_t blobBound(const ChunkInfo& c, const BlobOptions& o) {
  const uint64_t leaves = std::min(c.leafCount, c.nodeCount), inner = c.nodeCount - leaves;
  const uint64_t words =
      2 * uint64_t(c.nodeCount) + leaves * recordWords(o) + inner * (17 + recordWords(o)) + 64;
  return (words + gpu::kBlobHeaderWords + 2) * 4;
}

}  // namespace

void submitAndWait(Gpu& gpu, VkCommandBuffer cb, VkFence fence) {
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &cb;
  ISO_VK(vkResetFences(gpu.device, 1, &fence));
  ISO_VK(vkQueueSubmit(gpu.queue, 1, &submit, fence));
  ISO_VK(vkWaitForFences(gpu.device, 1, &fence, VK_TRUE, UINT64_MAX));
}

double renderFrame(Gpu& gpu, Renderer& renderer, const gpu::FrameParams& params, VkCommandBuffer cb,
                   VkFence fence) {
  renderer.prepare(params);
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  ISO_VK(vkBeginCommandBuffer(cb, &begin));
  renderer.record(cb);
  ISO_VK(vkEndCommandBuffer(cb));
  const auto t0 = std::chrono::steady_clock::now();
  submitAndWait(gpu, cb, fence);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  renderer.collect();
  return seconds;
}

Renderer::Renderer(Gpu& gpu, const Asset& asset, const Environment* environment,
                   RendererOptions options)
    : gpu_(gpu), asset_(asset), options_(options) {
  const auto chunks = asset.reader.chunks();
  const uint32_t chunkCount = uint32_t(chunks.size());
  constexpr auto storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
  constexpr auto dst = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
  constexpr auto src = VK_BUFFER_USAGE_TRANSFER_SRC_BIT;
  options_.capacityWidth = std::max(options.capacityWidth, options.width);
  options_.capacityHeight = std::max(options.capacityHeight, options.height);
  const uint64_t pixelsBytes = uint64_t(options_.capacityWidth) * options_.capacityHeight * 4;
  const uint64_t envBytes = environment ? environment->texels.size() * 4 : 16;
  uint64_t stagingBytes = 0, fileBytes = 0;  // the largest blob; all blobs
  for (const ChunkInfo& c : chunks)
    if (c.kind == kSurfaceKind) {
      const uint64_t bound = blobBound(c, asset.blob);
      stagingBytes = std::max(stagingBytes, bound);
      fileBytes += (bound + kPageBytes - 1) / kPageBytes * kPageBytes;
    }
  const uint64_t stagingBound = stagingBytes;
  stagingBytes = std::max(stagingBytes, std::min(options.uploadBytes, fileBytes));
  const uint64_t fixed =
      bufferFootprint(gpu, sizeof(gpu::FrameParams), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT) +
      bufferFootprint(gpu, uint64_t(chunkCount) * 16, storage) +
      bufferFootprint(gpu, (gpu::kFeedbackHeaderWords + 2 * uint64_t(chunkCount)) * 4, storage) +
      bufferFootprint(gpu, pixelsBytes, storage | src) + bufferFootprint(gpu, envBytes, storage) +
      bufferFootprint(gpu, stagingBytes, src);
  const uint64_t maxBuffer = uint64_t(1) << 30;  // the pool is addressed, not bound
  uint64_t poolPages = options.vram > fixed + kPageBytes ? (options.vram - fixed) / kPageBytes : 0;
  // Each buffer's memory may round up (alignment); leave a page a buffer for it. A pool larger
  // than the whole file would be wasted.
  // A chunk's pages are consecutive in one buffer: buffers hold the largest blob at least, and
  // each may leave up to a blob's pages unused at its end.
  const uint64_t largest = (stagingBound + kPageBytes - 1) / kPageBytes;
  poolPages = poolPages > gpu::kPoolBuffers ? poolPages - gpu::kPoolBuffers : 0;
  poolPages = std::min(poolPages, fileBytes / kPageBytes + gpu::kPoolBuffers * largest);
  const uint64_t maxPagesPerBuffer = std::bit_floor(maxBuffer / kPageBytes);
  pagesPerBuffer_ = uint32_t(std::min<uint64_t>(
      maxPagesPerBuffer,
      std::bit_ceil(std::max((poolPages + gpu::kPoolBuffers - 1) / gpu::kPoolBuffers, largest))));
  pagesPerBuffer_ = std::max<uint32_t>(pagesPerBuffer_, 1);
  poolPages = std::min<uint64_t>(poolPages, uint64_t(pagesPerBuffer_) * gpu::kPoolBuffers);
  if (poolPages == 0)
    throw std::runtime_error(
        fmt::format("--vram {} is too small: the frame buffers and tables alone take {} bytes",
                    options.vram, fixed));
  cache_ = std::make_unique<ChunkCache>(asset.reader, asset.tree, asset.blob, uint32_t(poolPages),
                                        pagesPerBuffer_);
  // What is made here is destroyed with its member if a later step throws.
  params_ = createBuffer(gpu, sizeof(gpu::FrameParams), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, true);
  chunkTable_ = createBuffer(gpu, uint64_t(chunkCount) * 16, storage, true);
  feedback_ =
      createBuffer(gpu, (gpu::kFeedbackHeaderWords + 2 * uint64_t(chunkCount)) * 4, storage, true);
  output_ = createBuffer(gpu, pixelsBytes, storage | src, true);
  environment_ = createBuffer(gpu, envBytes, storage, true);
  staging_ = createBuffer(gpu, stagingBytes, src, true);
  for (uint64_t first = 0; first < poolPages; first += pagesPerBuffer_) {
    const uint64_t pages = std::min<uint64_t>(pagesPerBuffer_, poolPages - first);
    pool_.push_back(createBuffer(gpu, pages * kPageBytes,
                                 dst | VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT, false));
  }
  if (environment)
    std::memcpy(environment_.mapped, environment->texels.data(), envBytes);
  else
    std::memset(environment_.mapped, 0, envBytes);
  std::memset(feedback_.mapped, 0, feedback_.size);
  auto* table = static_cast<gpu::ChunkEntry*>(chunkTable_.mapped);
  for (uint32_t i = 0; i < chunkCount; ++i)
    table[i].state = {gpu::kNotResident, chunks[i].level,
                      glm::floatBitsToUint(chunks[i].geometricError), chunks[i].parent};

  const uint32_t counts[] = {1, 1, 1, 1};
  ISO_CHECK(std::has_single_bit(options.workgroupSize) && options.workgroupSize >= 8 &&
            options.workgroupSize <= 1024);
  // kFloatDistances, kFlatTraversal, the workgroup size (trace.comp.glsl).
  const uint32_t constants[] = {asset.blob.floatDistances ? 1u : 0u,
                                options.flatTraversal ? 1u : 0u, options.workgroupSize};
  pipeline_ = createComputePipeline(gpu, kTraceSpirv, counts, constants);
  std::vector<VkDescriptorBufferInfo> infos;
  infos.push_back({params_.buffer, 0, VK_WHOLE_SIZE});
  infos.push_back({chunkTable_.buffer, 0, VK_WHOLE_SIZE});
  infos.push_back({feedback_.buffer, 0, VK_WHOLE_SIZE});
  infos.push_back({output_.buffer, 0, VK_WHOLE_SIZE});
  infos.push_back({environment_.buffer, 0, VK_WHOLE_SIZE});
  std::vector<VkWriteDescriptorSet> writes(5, {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET});
  for (uint32_t i = 0; i < 5; ++i) {
    writes[i].dstSet = pipeline_.set;
    writes[i].dstBinding = i;
    writes[i].descriptorCount = 1;
    writes[i].descriptorType =
        i == 0 ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &infos[i];
  }
  vkUpdateDescriptorSets(gpu.device, uint32_t(writes.size()), writes.data(), 0, nullptr);
  setup_.width = options.width;
  setup_.height = options.height;
  setup_.topChunk = asset.tree.topChunk();
  setup_.chunkCount = chunkCount;
  setup_.poolWordsLog2 = uint32_t(std::countr_zero(uint64_t(pagesPerBuffer_) * gpu::kPageWords));
  setup_.poolWords = uint32_t(std::min<uint64_t>(poolPages * gpu::kPageWords, UINT32_MAX));
  setup_.environmentWidth = environment ? environment->width : 0;
  setup_.environmentHeight = environment ? environment->height : 0;
  setup_.blob = asset.blob;
  setup_.swapRedBlue = options.swapRedBlue;
  setup_.requests = options.streaming;
  setup_.flatTraversal = options.flatTraversal;
  stats_.poolBytes = poolPages * kPageBytes;
}

Renderer::~Renderer() {
  // The buffers and the pipeline go with their members, once the device is done with them.
  if (gpu_.device) vkDeviceWaitIdle(gpu_.device);
  cache_.reset();
}

void Renderer::resize(uint32_t width, uint32_t height) {
  ISO_CHECK(width > 0 && height > 0 && width <= options_.capacityWidth &&
            height <= options_.capacityHeight);
  options_.width = setup_.width = width;
  options_.height = setup_.height = height;
}

void Renderer::prepare(gpu::FrameParams params) {
  if (auto error = cache_->error()) throw std::runtime_error(*error);
  ++frame_;
  stats_.frame = frame_;
  std::vector<uint32_t> evicted;
  const auto uploads = cache_->place(frame_ - 1, staging_.size, evicted);
  auto* table = static_cast<gpu::ChunkEntry*>(chunkTable_.mapped);
  for (uint32_t c : evicted) table[c].state.x = gpu::kNotResident;
  copies_.clear();
  uint64_t offset = 0;
  auto* staging = static_cast<std::byte*>(staging_.mapped);
  for (const ChunkCache::Upload& up : uploads) {
    const uint64_t bytes = up.words.size() * 4;
    ISO_CHECK(offset + bytes <= staging_.size);
    std::memcpy(staging + offset, up.words.data(), bytes);
    copies_.push_back({up.firstPage / pagesPerBuffer_,
                       {offset, (up.firstPage % pagesPerBuffer_) * kPageBytes, bytes}});
    table[up.chunk].state.x = up.firstPage;
    offset += bytes;
  }
  stats_.uploadedChunks = uint32_t(uploads.size());
  stats_.uploadedBytes = offset;
  stats_.streamedBytes += offset;
  stats_.evicted = uint32_t(evicted.size());
  params.image.w = frame_;
  params.options.z = setup_.topChunk;
  params.options.w = setup_.chunkCount;
  params.pool = {setup_.poolWordsLog2, setup_.poolWords, setup_.environmentWidth,
                 setup_.environmentHeight};
  for (size_t b = 0; b < gpu::kPoolBuffers; ++b) {
    const VkDeviceAddress a = pool_[b < pool_.size() ? b : 0].address;
    params.poolAddress[b / 2][2 * (b % 2)] = uint32_t(a);
    params.poolAddress[b / 2][2 * (b % 2) + 1] = uint32_t(a >> 32);
  }
  if (setup_.requests)
    params.options.x |= gpu::kOptionRequests;
  else
    params.options.x &= ~gpu::kOptionRequests;
  std::memcpy(params_.mapped, &params, sizeof params);
  for (uint32_t kind :
       {gpu::kFeedbackPrimaryRays, gpu::kFeedbackShadowRays, gpu::kFeedbackSecondaryRays})
    static_cast<uint32_t*>(feedback_.mapped)[kind] = 0;
}

void Renderer::record(VkCommandBuffer cb) {
  for (const Copy& c : copies_)
    vkCmdCopyBuffer(cb, staging_.buffer, pool_[c.buffer].buffer, 1, &c.region);
  VkMemoryBarrier barrier{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  barrier.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT;
  barrier.dstAccessMask =
      VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_UNIFORM_READ_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &barrier, 0, nullptr, 0,
                       nullptr);
  vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.pipeline);
  vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.layout, 0, 1,
                          &pipeline_.set, 0, nullptr);
  // Tiles of the workgroup's size, as the shader lays them out.
  const uint32_t tileWidth = 1u << ((std::countr_zero(options_.workgroupSize) + 1) / 2);
  const uint32_t tileHeight = options_.workgroupSize / tileWidth;
  const uint32_t tiles = ((options_.width + tileWidth - 1) / tileWidth) *
                         ((options_.height + tileHeight - 1) / tileHeight);
  vkCmdDispatch(cb, tiles, 1, 1);
  VkMemoryBarrier after{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  after.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  after.dstAccessMask = VK_ACCESS_HOST_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT;
  vkCmdPipelineBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                       VK_PIPELINE_STAGE_HOST_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &after, 0,
                       nullptr, 0, nullptr);
}

void Renderer::collect() {
  const auto* fb = static_cast<const uint32_t*>(feedback_.mapped);
  const uint32_t n = setup_.chunkCount;
  stats_.rays = {fb[gpu::kFeedbackPrimaryRays], fb[gpu::kFeedbackShadowRays],
                 fb[gpu::kFeedbackSecondaryRays]};
  stats_.requested = 0;
  for (uint32_t c = 0; c < n; ++c) {
    if (fb[gpu::kFeedbackHeaderWords + c] == frame_) {
      if (!cache_->resident(c)) ++stats_.requested;
      cache_->request(c, frame_);
    }
    if (fb[gpu::kFeedbackHeaderWords + n + c] == frame_) cache_->use(c, frame_);
  }
  stats_.resident = cache_->residentChunks();
  stats_.pending = cache_->pendingChunks();
  stats_.vramInUse = gpu_.memoryInUse;
  stats_.vramPeak = gpu_.memoryPeak;
  stats_.poolBytesInUse = uint64_t(cache_->pagesInUse()) * kPageBytes;
  const bool progress = stats_.uploadedChunks > 0 || !cache_->idle();
  stalledFrames_ = (!progress && stats_.requested > 0) ? stalledFrames_ + 1 : 0;
}

std::vector<uint32_t> Renderer::pixels() const {
  const auto* p = static_cast<const uint32_t*>(output_.mapped);
  return {p, p + size_t(options_.width) * options_.height};
}

}  // namespace iso::viewer
