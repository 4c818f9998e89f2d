// The viewer's GPU frames and streaming uploads (renderer.h).
#include "viewer/renderer.h"

#include <fmt/core.h>
#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <initializer_list>
#include <span>

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

// The staging bytes a frame may fill: the largest blob (a frame always takes one), or the upload
// budget when larger (but no more than the whole file); and the pool bytes of all blobs.
struct BlobSizes {
  uint64_t stagingRegion = 0, fileBytes = 0, largestBlob = 0;
};

// The same of a splat blob (buildSplatBlob): header, 6 words a point, at most 2 a point of
// boxes and 6 for each level's rounding.
uint64_t splatBlobBound(const ChunkInfo& c) {
  return (gpu::kSplatHeaderWords + 8 * c.pointCount + 6 * gpu::kSplatMaxLevels) * 4;
}

BlobSizes blobSizes(const Asset& asset, uint64_t uploadBytes) {
  BlobSizes b;
  const auto add = [&](uint64_t bound) {
    b.stagingRegion = std::max(b.stagingRegion, bound);
    b.fileBytes += (bound + kPageBytes - 1) / kPageBytes * kPageBytes;
  };
  for (const ChunkInfo& c : asset.reader.chunks()) {
    if (c.kind == kSurfaceKind) add(blobBound(c, asset.blob));
    if (c.kind == kPointsKind && asset.splats) add(splatBlobBound(c));
  }
  if (asset.splats) add(asset.splats->words.size() * 4);
  b.largestBlob = b.stagingRegion;
  b.stagingRegion = std::max(b.stagingRegion, std::min(uploadBytes, b.fileBytes));
  return b;
}

constexpr auto kStorage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
constexpr auto kUniform = VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT;
constexpr auto kTransferDst = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
constexpr auto kTransferSrc = VK_BUFFER_USAGE_TRANSFER_SRC_BIT;

// A slot's four timestamps (start, copies done, photons done, dispatch done), copied by the GPU
// into a host-visible buffer: reading them with vkGetQueryPoolResults would make lavapipe wait
// for its whole queue, frames in flight included.
constexpr uint32_t kTimestamps = 4;
constexpr uint64_t kTimestampBytes = kTimestamps * sizeof(uint64_t);

// The wavefront's queue (trace.comp.glsl): the count of hits, the shading pass's indirect
// dispatch (x, y, z), the wave's first tile, the count of mirror rays, two unused words, the
// mirror pass's indirect dispatch (x, y, z), one unused word.
constexpr uint64_t kQueueBytes = 48;
constexpr uint32_t kQueueMirrorCount = 5, kQueueMirrorDispatch = 8;
constexpr auto kQueueUsage = kStorage | kTransferDst | VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT;
constexpr uint64_t kHitBytes = 64;     // four vec4s a hit
constexpr uint64_t kPathBytes = 64;    // four vec4s a path that reflects a mirror ray, and
constexpr uint64_t kPendingBytes = 4;  // its index while its ray waits
// Pixels a wave of a wavefront frame (its hits, paths and pending rays: 14.5 MiB), so that large
// pictures fit small budgets.
constexpr uint64_t kWavePixels = uint64_t(1) << 17;
// The pipelines, by the shader's kPass (trace.comp.glsl): one kernel, the camera rays, the
// shading of hits, the cones, the mirror rays, the caustic photons.
enum Variant : uint32_t { kOneKernel, kCameraRays, kShadeHits, kCones, kMirrorRays, kPhotons };

// The caustic map's bytes (shared.h), or a word without caustics.
uint64_t causticBytes(bool caustics) {
  return caustics ? uint64_t(3) * gpu::kCausticCells * gpu::kCausticCells * 4 : 4;
}

// The frame parameters the caustic map depends on: everything but the camera, the picture, the
// frame number and the pool's addresses (photons ignore them).
std::vector<std::byte> causticKey(gpu::FrameParams p) {
  p.eye = glm::vec4(0.0f, 0.0f, 0.0f, p.eye.w);
  p.right = p.up = p.forward = glm::vec4(0.0f);
  p.image = glm::uvec4(0u);
  p.pool = glm::uvec4(0u);
  for (auto& a : p.poolAddress) a = glm::uvec4(0u);
  p.options.x &= ~(gpu::kOptionSwapRB | gpu::kOptionTileCones);
  const auto* bytes = reinterpret_cast<const std::byte*>(&p);
  return {bytes, bytes + sizeof p};
}

// The workgroups of a frame: tiles of the workgroup's size, as the shader lays them out.
uint32_t tileCount(uint32_t width, uint32_t height, uint32_t workgroupSize) {
  const uint32_t tileWidth = 1u << ((std::countr_zero(workgroupSize) + 1) / 2);
  const uint32_t tileHeight = workgroupSize / tileWidth;
  return ((width + tileWidth - 1) / tileWidth) * ((height + tileHeight - 1) / tileHeight);
}

// A memory barrier: what the commands before wrote in srcStage, made visible to dstStage.
void memoryBarrier(VkCommandBuffer cb, VkPipelineStageFlags srcStage, VkAccessFlags srcAccess,
                   VkPipelineStageFlags dstStage, VkAccessFlags dstAccess) {
  VkMemoryBarrier b{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  b.srcAccessMask = srcAccess;
  b.dstAccessMask = dstAccess;
  vkCmdPipelineBarrier(cb, srcStage, dstStage, 0, 1, &b, 0, nullptr, 0, nullptr);
}

uint64_t feedbackBytes(uint32_t chunkCount) {
  return (gpu::kFeedbackHeaderWords + 2 * uint64_t(chunkCount)) * 4;
}

// Device memory of everything but the pool: per frame slot its parameters, chunk table, feedback
// and staging region; the output, the queue and the other storage buffers (the environment map,
// the wavefront's hits, paths and pending rays, the tiles' starts) once.
uint64_t fixedBytes(Gpu& gpu, uint32_t chunkCount, uint32_t slots, uint64_t stagingRegion,
                    uint64_t pixelsBytes, std::initializer_list<uint64_t> storageBytes) {
  const uint64_t perSlot =
      bufferFootprint(gpu, sizeof(gpu::FrameParams), kUniform) +
      bufferFootprint(gpu, uint64_t(chunkCount) * 16, kStorage) +
      bufferFootprint(gpu, feedbackBytes(chunkCount), kStorage) +
      (gpu.timestampValidBits > 0 ? bufferFootprint(gpu, kTimestampBytes, kTransferDst) : 0);
  uint64_t bytes = slots * perSlot + bufferFootprint(gpu, pixelsBytes, kStorage | kTransferSrc) +
                   bufferFootprint(gpu, slots * stagingRegion, kTransferSrc) +
                   bufferFootprint(gpu, kQueueBytes, kQueueUsage);
  for (const uint64_t b : storageBytes) bytes += bufferFootprint(gpu, b, kStorage);
  return bytes;
}

// Pool pages under the budget: what the rest leaves, less a page a buffer for alignment, in
// buffers of pagesPerBuffer pages. A chunk's pages are consecutive in one buffer: buffers hold
// the largest blob at least, and each may leave up to a blob's pages unused at its end; more than
// the whole file's blobs and that slack would be wasted.
uint64_t poolPagesFor(uint64_t vram, uint64_t fixed, uint64_t fileBytes, uint64_t largestBlob,
                      uint32_t& pagesPerBuffer) {
  const uint64_t maxBuffer = uint64_t(1) << 30;  // the pool is addressed, not bound
  const uint64_t largest = (largestBlob + kPageBytes - 1) / kPageBytes;
  uint64_t poolPages = vram > fixed + kPageBytes ? (vram - fixed) / kPageBytes : 0;
  poolPages = poolPages > gpu::kPoolBuffers ? poolPages - gpu::kPoolBuffers : 0;
  poolPages = std::min(poolPages, fileBytes / kPageBytes + gpu::kPoolBuffers * largest);
  const uint64_t maxPagesPerBuffer = std::bit_floor(maxBuffer / kPageBytes);
  pagesPerBuffer = uint32_t(std::min<uint64_t>(
      maxPagesPerBuffer,
      std::bit_ceil(std::max((poolPages + gpu::kPoolBuffers - 1) / gpu::kPoolBuffers, largest))));
  pagesPerBuffer = std::max<uint32_t>(pagesPerBuffer, 1);
  return std::min<uint64_t>(poolPages, uint64_t(pagesPerBuffer) * gpu::kPoolBuffers);
}

}  // namespace

void renderFrame(Renderer& renderer, const gpu::FrameParams& params) {
  renderer.prepare(params);
  renderer.record();
  renderer.submit();
}

Renderer::Renderer(Gpu& gpu, const Asset& asset, const Environment* environment,
                   RendererOptions options)
    : gpu_(gpu), asset_(asset), options_(options) {
  ISO_CHECK(options.framesInFlight >= 1 && options.framesInFlight <= kMaxFramesInFlight);
  ISO_CHECK(std::has_single_bit(options.workgroupSize) && options.workgroupSize >= 8 &&
            options.workgroupSize <= 1024);
  const auto chunks = asset.reader.chunks();
  const uint32_t chunkCount = uint32_t(chunks.size()) + (asset.splats ? 1 : 0);
  options_.capacityWidth = std::max(options.capacityWidth, options.width);
  options_.capacityHeight = std::max(options.capacityHeight, options.height);
  const uint64_t pixelsBytes = uint64_t(options_.capacityWidth) * options_.capacityHeight * 4;
  const uint64_t envBytes = environment ? environment->texels.size() * 4 : 16;
  const BlobSizes sizes = blobSizes(asset, options.uploadBytes);
  const uint32_t capacityTiles =
      tileCount(options_.capacityWidth, options_.capacityHeight, options.workgroupSize);
  waveTiles_ = std::min<uint32_t>(capacityTiles, uint32_t(kWavePixels / options.workgroupSize));
  const uint64_t wavePixels = options.oneKernel ? 1 : uint64_t(waveTiles_) * options.workgroupSize;
  const uint64_t hitsBytes = wavePixels * kHitBytes;
  const uint64_t pathsBytes = wavePixels * kPathBytes, pendingBytes = wavePixels * kPendingBytes;
  const uint64_t startsBytes = uint64_t(capacityTiles) * 4;  // a float a tile
  const uint64_t fixed =
      fixedBytes(gpu, chunkCount, options.framesInFlight, sizes.stagingRegion, pixelsBytes,
                 {envBytes, hitsBytes, pathsBytes, pendingBytes, startsBytes,
                  causticBytes(options.caustics)});
  const uint64_t poolPages =
      poolPagesFor(options.vram, fixed, sizes.fileBytes, sizes.largestBlob, pagesPerBuffer_);
  if (poolPages == 0)
    throw std::runtime_error(
        fmt::format("--vram {} is too small: the frame buffers and tables alone take {} bytes",
                    options.vram, fixed));
  cache_ = std::make_unique<ChunkCache>(asset.reader, asset.tree, asset.blob, uint32_t(poolPages),
                                        pagesPerBuffer_, asset.splats ? &*asset.splats : nullptr);
  // What is made here is destroyed with its member if a later step throws.
  output_ = createBuffer(gpu, pixelsBytes, kStorage | kTransferSrc, true);
  environment_ = createBuffer(gpu, envBytes, kStorage, true);
  staging_ = createBuffer(gpu, options.framesInFlight * sizes.stagingRegion, kTransferSrc, true);
  hits_ = createBuffer(gpu, hitsBytes, kStorage, false);
  queue_ = createBuffer(gpu, kQueueBytes, kQueueUsage, false);
  starts_ = createBuffer(gpu, startsBytes, kStorage, false);
  paths_ = createBuffer(gpu, pathsBytes, kStorage, false);
  pending_ = createBuffer(gpu, pendingBytes, kStorage, false);
  caustics_ = createBuffer(gpu, causticBytes(options.caustics), kStorage | kTransferDst, false);
  for (uint64_t first = 0; first < poolPages; first += pagesPerBuffer_) {
    const uint64_t pages = std::min<uint64_t>(pagesPerBuffer_, poolPages - first);
    pool_.push_back(createBuffer(gpu, pages * kPageBytes,
                                 kTransferDst | VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT, false));
  }
  if (environment)
    std::memcpy(environment_.mapped, environment->texels.data(), envBytes);
  else
    std::memset(environment_.mapped, 0, envBytes);
  table_.resize(chunkCount);
  for (uint32_t i = 0; i < chunkCount; ++i)
    table_[i].state = i < chunks.size()
                          ? glm::uvec4{gpu::kNotResident, chunks[i].level,
                                       glm::floatBitsToUint(chunks[i].geometricError),
                                       chunks[i].parent}
                          : glm::uvec4{gpu::kNotResident, 0u, 0u, gpu::kNotResident};
  // Bindings 1 to 10, then the point set surface's parameters and buffers (11 to 22).
  std::array<uint32_t, 10 + 1 + gpu::kPssStorageBindings> counts;
  counts.fill(1);
  if (options.pss) {
    pss_ = std::make_unique<PssBuffers>(gpu, options.pss->surface.get(), options.pss->colors);
    pss_->setVolume(options.pss->volume.get());
  } else {
    pss_ = std::make_unique<PssBuffers>(gpu, nullptr, std::vector<glm::vec3>{});
  }
  const uint32_t pss = options.pss ? 1u : 0u;
  // kFloatDistances, kFlatTraversal, the workgroup size, kPass (trace.comp.glsl): the variants
  // the options use (with oneKernel, one kernel and the cones).
  std::vector<std::vector<uint32_t>> variants;
  for (const Variant pass : {kOneKernel, kCones, kCameraRays, kShadeHits, kMirrorRays, kPhotons}) {
    if (options.oneKernel && pass != kOneKernel && pass != kCones && pass != kPhotons) continue;
    if (pass == kPhotons && !options.caustics) continue;
    for (uint32_t splats = 0; splats < (asset.splats ? 2u : 1u); ++splats) {
      pipelineIndex_[pass][splats] = uint32_t(variants.size());
      variants.push_back({asset.blob.floatDistances ? 1u : 0u, options.flatTraversal ? 1u : 0u,
                          options.workgroupSize, pass, splats, pss});
    }
    if (!asset.splats) pipelineIndex_[pass][1] = pipelineIndex_[pass][0];
  }
  pipeline_ = createComputePipeline(gpu, kTraceSpirv, counts, variants, options.framesInFlight);
  createSlots(sizes.stagingRegion);
  setup_.width = options.width;
  setup_.height = options.height;
  setup_.topChunk = asset.tree.topChunk();
  setup_.chunkCount = chunkCount;
  setup_.poolWordsLog2 = uint32_t(std::countr_zero(uint64_t(pagesPerBuffer_) * gpu::kPageWords));
  setup_.poolWords = uint32_t(std::min<uint64_t>(poolPages * gpu::kPageWords, UINT32_MAX));
  setup_.environmentWidth = environment ? environment->width : 0;
  setup_.environmentHeight = environment ? environment->height : 0;
  setup_.blob = asset.blob;
  setup_.contentLo = asset.contentLo;
  setup_.contentHi = asset.contentHi;
  if (asset.splats) {
    setup_.splatIndex = asset.splats->chunk;
    setup_.splatRadius = asset.splats->typicalRadius;
  }
  setup_.swapRedBlue = options.swapRedBlue;
  setup_.requests = options.streaming;
  setup_.flatTraversal = options.flatTraversal;
  setup_.tileCones = options.tileCones;
  setup_.pss = options.pss != nullptr;
  stats_.poolBytes = poolPages * kPageBytes;
}

// Each slot's buffers, descriptor set, command buffer and fence; the timestamp queries when the
// queue has timestamps.
void Renderer::createSlots(uint64_t stagingRegion) {
  const uint32_t chunkCount = uint32_t(table_.size());
  slots_.resize(options_.framesInFlight);
  for (uint32_t i = 0; i < slots_.size(); ++i) {
    Slot& s = slots_[i];
    s.params = createBuffer(gpu_, sizeof(gpu::FrameParams), kUniform, true);
    s.pssParams = createBuffer(gpu_, sizeof(gpu::PssParams), kStorage, true);
    std::memset(s.pssParams.mapped, 0, sizeof(gpu::PssParams));
    s.table = createBuffer(gpu_, uint64_t(chunkCount) * 16, kStorage, true);
    s.feedback = createBuffer(gpu_, feedbackBytes(chunkCount), kStorage, true);
    std::memset(s.feedback.mapped, 0, s.feedback.size);
    if (gpu_.timestampValidBits > 0)
      s.timestamps = createBuffer(gpu_, kTimestampBytes, kTransferDst, true);
    s.set = pipeline_.sets[i];
    s.stagingOffset = i * stagingRegion;
    s.fence = createFence(gpu_, false);
    s.cb = allocateCommandBuffer(gpu_);
    writeDescriptors(s);
  }
  if (gpu_.timestampValidBits > 0) {
    queries_ = createTimestampQueries(gpu_, kTimestamps * uint32_t(slots_.size()));
    timestampSeconds_ = double(gpu_.properties.limits.timestampPeriod) * 1e-9;
    timestampMask_ =
        gpu_.timestampValidBits >= 64 ? ~uint64_t(0) : (uint64_t(1) << gpu_.timestampValidBits) - 1;
  }
}

void Renderer::writeDescriptors(const Slot& slot) {
  const VkDescriptorBufferInfo infos[] = {
      {slot.params.buffer, 0, VK_WHOLE_SIZE},   {slot.table.buffer, 0, VK_WHOLE_SIZE},
      {slot.feedback.buffer, 0, VK_WHOLE_SIZE}, {output_.buffer, 0, VK_WHOLE_SIZE},
      {environment_.buffer, 0, VK_WHOLE_SIZE},  {hits_.buffer, 0, VK_WHOLE_SIZE},
      {queue_.buffer, 0, VK_WHOLE_SIZE},        {starts_.buffer, 0, VK_WHOLE_SIZE},
      {paths_.buffer, 0, VK_WHOLE_SIZE},        {pending_.buffer, 0, VK_WHOLE_SIZE},
      {caustics_.buffer, 0, VK_WHOLE_SIZE}};
  std::vector<VkDescriptorBufferInfo> all(std::begin(infos), std::end(infos));
  all.push_back({slot.pssParams.buffer, 0, VK_WHOLE_SIZE});
  for (const Buffer* b : pss_->storage()) all.push_back({b->buffer, 0, VK_WHOLE_SIZE});
  writeComputeSet(gpu_, slot.set, all);
}

Renderer::~Renderer() {
  // The buffers and the pipeline go with their members, once the device is done with them.
  if (gpu_.device) {
    vkDeviceWaitIdle(gpu_.device);
    for (Slot& s : slots_)
      if (s.cb) vkFreeCommandBuffers(gpu_.device, gpu_.commandPool, 1, &s.cb);
  }
  cache_.reset();
}

void Renderer::resize(uint32_t width, uint32_t height) {
  ISO_CHECK(width > 0 && height > 0 && width <= options_.capacityWidth &&
            height <= options_.capacityHeight);
  finish();
  options_.width = setup_.width = width;
  options_.height = setup_.height = height;
}

void Renderer::prepare(gpu::FrameParams params) {
  ISO_CHECK(!prepared_);
  if (auto error = cache_->error()) throw std::runtime_error(*error);
  const uint32_t next = frame_ % uint32_t(slots_.size());
  // Slots are taken in turn, so the frame that held this one is the oldest in flight.
  while (std::find(inFlight_.begin(), inFlight_.end(), next) != inFlight_.end()) collectNext();
  ++frame_;
  current_ = next;
  prepared_ = true;
  Slot& slot = slots_[current_];
  slot.stats = {};
  slot.stats.frame = frame_;
  stage(slot);
  params.image.w = frame_;
  params.options.z = setup_.topChunk;
  splatsDrawn_ = (params.options.x & gpu::kOptionSplats) != 0u;
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
  if (!options_.caustics) params.caustics = glm::uvec4(0u);
  std::memcpy(slot.params.mapped, &params, sizeof params);
  if (options_.pss) {
    const gpu::PssParams q = options_.pss->params(params);
    std::memcpy(slot.pssParams.mapped, &q, sizeof q);
  }
  // The caustic map again when what it depends on changed, the resident chunks included.
  slot.photons = 0;
  if (params.caustics.x > 0) {
    std::vector<std::byte> key = causticKey(params);
    const auto version = reinterpret_cast<const std::byte*>(&residentVersion_);
    key.insert(key.end(), version, version + sizeof residentVersion_);
    if (key != causticKey_) {
      slot.photons = params.caustics.y;
      causticKey_ = std::move(key);
    }
  } else {
    causticKey_.clear();
  }
  // A wavefront for frames of one sample a pixel whose hits leave one mirror ray at most.
  slot.wavefront = !options_.oneKernel && params.image.z <= 1 && !refractionRays(params);
  slot.stats.twoPasses = slot.wavefront;
  slot.stats.mirrorBounces = slot.wavefront && secondaryRays(params) ? params.options.y : 0;
  for (uint32_t kind : {gpu::kFeedbackPrimaryRays, gpu::kFeedbackShadowRays,
                        gpu::kFeedbackSecondaryRays, gpu::kFeedbackPhotons})
    static_cast<uint32_t*>(slot.feedback.mapped)[kind] = 0;
}

// Place what the loader has ready, copy it into the slot's staging region, list the copies into
// the pool, and give the slot the chunk table as it now is. Frames in flight keep their tables,
// and the pages of chunks evicted here wait for them (gpuProgress).
void Renderer::stage(Slot& slot) {
  cache_->gpuProgress(frame_ - 1, lastCollected_);
  std::vector<uint32_t> evicted;
  const uint64_t region = staging_.size / slots_.size();
  const auto uploads = cache_->place(lastCollected_, region, evicted);
  for (uint32_t c : evicted) table_[c].state.x = gpu::kNotResident;
  slot.copies.clear();
  uint64_t offset = 0;
  auto* staging = static_cast<std::byte*>(staging_.mapped) + slot.stagingOffset;
  for (const ChunkCache::Upload& up : uploads) {
    const uint64_t bytes = up.words.size() * 4;
    ISO_CHECK(offset + bytes <= region);
    std::memcpy(staging + offset, up.words.data(), bytes);
    slot.copies.push_back(
        {up.firstPage / pagesPerBuffer_,
         {slot.stagingOffset + offset, (up.firstPage % pagesPerBuffer_) * kPageBytes, bytes}});
    table_[up.chunk].state.x = up.firstPage;
    offset += bytes;
  }
  std::memcpy(slot.table.mapped, table_.data(), table_.size() * sizeof(gpu::ChunkEntry));
  streamedBytes_ += offset;
  slot.stats.uploadedChunks = uint32_t(uploads.size());
  slot.stats.uploadedBytes = offset;
  slot.stats.streamedBytes = streamedBytes_;
  slot.stats.evicted = uint32_t(evicted.size());
  if (!uploads.empty() || !evicted.empty()) ++residentVersion_;
}

VkCommandBuffer Renderer::record() {
  ISO_CHECK(prepared_);
  const Slot& slot = slots_[current_];
  VkCommandBuffer cb = slot.cb;
  ISO_VK(vkResetCommandBuffer(cb, 0));
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  ISO_VK(vkBeginCommandBuffer(cb, &begin));
  const uint32_t query = kTimestamps * current_;
  if (hasTimestamps()) {
    vkCmdResetQueryPool(cb, queries_, query, kTimestamps);
    vkCmdWriteTimestamp(cb, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_, query);
  }
  // The copies write only pages that no frame in flight reads (evicted pages wait), so they need
  // no barrier against earlier frames.
  for (const Copy& c : slot.copies)
    vkCmdCopyBuffer(cb, staging_.buffer, pool_[c.buffer].buffer, 1, &c.region);
  // Before the dispatch: this frame's copies, and earlier frames' use of the one output buffer
  // (their dispatches write it; a window copies it into a swapchain image).
  memoryBarrier(
      cb,
      VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT |
          VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
      VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT | VK_ACCESS_SHADER_WRITE_BIT,
      VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
      VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_UNIFORM_READ_BIT);
  if (hasTimestamps())
    vkCmdWriteTimestamp(cb, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_, query + 1);
  vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.layout, 0, 1, &slot.set, 0,
                          nullptr);
  if (slot.photons > 0) recordPhotons(cb, slot.photons);
  if (hasTimestamps())
    vkCmdWriteTimestamp(cb, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_, query + 2);
  const uint32_t tiles = tileCount(options_.width, options_.height, options_.workgroupSize);
  if (setup_.tileCones) recordCones(cb, tiles);
  if (slot.wavefront) {
    recordWavefront(cb, tiles, slot.stats.mirrorBounces);
  } else {
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipelineOf(kOneKernel));
    vkCmdDispatch(cb, tiles, 1, 1);
  }
  if (hasTimestamps()) {
    vkCmdWriteTimestamp(cb, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_, query + 3);
    vkCmdCopyQueryPoolResults(cb, queries_, query, kTimestamps, slot.timestamps.buffer, 0,
                              sizeof(uint64_t),
                              VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT);
  }
  memoryBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
                VK_PIPELINE_STAGE_HOST_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                VK_ACCESS_HOST_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT);
  return cb;
}

// The caustic map recomputed: emptied once the frames before have read it, then the photons of
// all lights summed into it, before the passes that read it.
void Renderer::recordPhotons(VkCommandBuffer cb, uint32_t photons) {
  memoryBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT,
                VK_ACCESS_TRANSFER_WRITE_BIT);
  vkCmdFillBuffer(cb, caustics_.buffer, 0, VK_WHOLE_SIZE, 0u);
  memoryBarrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipelineOf(kPhotons));
  // (Each invocation takes photons a whole dispatch apart: the groups stay under every
  // device's limit.)
  const uint32_t groups = std::min<uint32_t>(
      (photons + options_.workgroupSize - 1) / options_.workgroupSize, 65535u);
  vkCmdDispatch(cb, groups, 1, 1);
  memoryBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
}

// The cones of the frame's tiles (cone.h), a tile an invocation, before the passes that read them.
void Renderer::recordCones(VkCommandBuffer cb, uint32_t tiles) {
  vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipelineOf(kCones));
  vkCmdDispatch(cb, (tiles + options_.workgroupSize - 1) / options_.workgroupSize, 1, 1);
  memoryBarrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
}

// The passes of a wavefront frame, a wave of tiles at a time: the queue emptied, the camera rays
// filling it, the shading of their hits dispatched from it; then, per bounce, the mirror rays
// that shading queued and the shading of their hits.
void Renderer::recordWavefront(VkCommandBuffer cb, uint32_t tiles, uint32_t bounces) {
  constexpr auto kCompute = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
  constexpr auto kIndirect = VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT;
  constexpr auto kTransfer = VK_PIPELINE_STAGE_TRANSFER_BIT;
  constexpr auto kShaderAccess = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
  constexpr auto kAfterPass = kShaderAccess | VK_ACCESS_INDIRECT_COMMAND_READ_BIT;
  // Queue words written once the passes before have read them, and read by the next.
  const auto setQueue = [&](uint32_t word, std::span<const uint32_t> values) {
    memoryBarrier(cb, kCompute | kIndirect, kAfterPass, kTransfer, VK_ACCESS_TRANSFER_WRITE_BIT);
    vkCmdUpdateBuffer(cb, queue_.buffer, word * 4, values.size_bytes(), values.data());
    memoryBarrier(cb, kTransfer, VK_ACCESS_TRANSFER_WRITE_BIT, kCompute | kIndirect, kAfterPass);
  };
  const auto pass = [&](Variant v) {
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipelineOf(v));
  };
  const auto passDone = [&] {
    memoryBarrier(cb, kCompute, VK_ACCESS_SHADER_WRITE_BIT, kCompute | kIndirect, kAfterPass);
  };
  for (uint32_t first = 0; first < tiles; first += waveTiles_) {
    // No hits, no mirror rays; 0 × 1 × 1 workgroups for both dispatches.
    const uint32_t empty[12] = {0, 0, 1, 1, first, 0, 0, 0, 0, 1, 1, 0};
    setQueue(0, empty);
    pass(kCameraRays);
    vkCmdDispatch(cb, std::min(waveTiles_, tiles - first), 1, 1);
    passDone();
    pass(kShadeHits);
    vkCmdDispatchIndirect(cb, queue_.buffer, 4);
    for (uint32_t bounce = 0; bounce < bounces; ++bounce) {
      passDone();
      const uint32_t none[2] = {0, 0};  // the hits shaded: their count and dispatch
      setQueue(0, none);
      pass(kMirrorRays);
      vkCmdDispatchIndirect(cb, queue_.buffer, kQueueMirrorDispatch * 4);
      passDone();
      const uint32_t noRays[4] = {0, 0, 0, 0};  // the rays traced: their count, and dispatch x
      setQueue(kQueueMirrorCount, noRays);
      pass(kShadeHits);
      vkCmdDispatchIndirect(cb, queue_.buffer, 4);
    }
  }
}

void Renderer::submit(VkSemaphore wait, VkPipelineStageFlags waitStage, VkSemaphore signal) {
  ISO_CHECK(prepared_);
  Slot& slot = slots_[current_];
  ISO_VK(vkEndCommandBuffer(slot.cb));
  VkSubmitInfo info{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  info.commandBufferCount = 1;
  info.pCommandBuffers = &slot.cb;
  if (wait) {
    info.waitSemaphoreCount = 1;
    info.pWaitSemaphores = &wait;
    info.pWaitDstStageMask = &waitStage;
  }
  if (signal) {
    info.signalSemaphoreCount = 1;
    info.pSignalSemaphores = &signal;
  }
  VkFence fence = slot.fence;
  ISO_VK(vkResetFences(gpu_.device, 1, &fence));
  ISO_VK(vkQueueSubmit(gpu_.queue, 1, &info, fence));
  inFlight_.push_back(current_);
  prepared_ = false;
}

bool Renderer::collectNext() {
  if (inFlight_.empty()) return false;
  const uint32_t index = inFlight_.front();
  Slot& slot = slots_[index];
  VkFence fence = slot.fence;
  ISO_VK(vkWaitForFences(gpu_.device, 1, &fence, VK_TRUE, UINT64_MAX));
  inFlight_.erase(inFlight_.begin());
  slot.stats.completed = std::chrono::steady_clock::now();
  readTimestamps(slot, slot.stats);
  collect(slot);
  return true;
}

void Renderer::finish() {
  while (collectNext()) {
  }
}

void Renderer::readTimestamps(const Slot& slot, FrameStats& stats) const {
  if (!hasTimestamps()) return;
  uint64_t t[kTimestamps];
  std::memcpy(t, slot.timestamps.mapped, sizeof t);
  const auto between = [&](int a, int b) {
    return double((t[b] - t[a]) & timestampMask_) * timestampSeconds_;
  };
  stats.gpuSeconds = between(0, 3);
  stats.dispatchSeconds = between(1, 3);
  stats.photonSeconds = between(1, 2);
  stats.gpuStart = double(t[0] & timestampMask_) * timestampSeconds_;
  stats.gpuEnd = double(t[3] & timestampMask_) * timestampSeconds_;
}

// The slot's feedback, read once its frame completed: the rays by kind, the chunks its rays asked
// for that its table lacked (queued for the loader), and the chunks they went through (LRU).
void Renderer::collect(Slot& slot) {
  const auto* fb = static_cast<const uint32_t*>(slot.feedback.mapped);
  const auto* table = static_cast<const gpu::ChunkEntry*>(slot.table.mapped);
  const uint32_t n = setup_.chunkCount;
  const uint32_t frame = uint32_t(slot.stats.frame);
  FrameStats& s = slot.stats;
  s.rays = {fb[gpu::kFeedbackPrimaryRays], fb[gpu::kFeedbackShadowRays],
            fb[gpu::kFeedbackSecondaryRays]};
  s.photons = fb[gpu::kFeedbackPhotons];
  for (uint32_t c = 0; c < n; ++c) {
    if (fb[gpu::kFeedbackHeaderWords + c] == frame) {
      if (table[c].state.x == gpu::kNotResident) ++s.requested;
      cache_->request(c, frame);
    }
    if (fb[gpu::kFeedbackHeaderWords + n + c] == frame) cache_->use(c, frame);
  }
  lastCollected_ = frame;
  s.resident = cache_->residentChunks();
  s.pending = cache_->pendingChunks();
  s.vramInUse = gpu_.memoryInUse;
  s.vramPeak = gpu_.memoryPeak;
  s.poolBytes = stats_.poolBytes;
  s.poolBytesInUse = uint64_t(cache_->pagesInUse()) * kPageBytes;
  const bool progress = s.uploadedChunks > 0 || !cache_->idle() || cache_->retiredPages() > 0;
  stalledFrames_ = (!progress && s.requested > 0) ? stalledFrames_ + 1 : 0;
  stats_ = s;
  if (onCollected_) onCollected_(stats_);
}

std::vector<uint32_t> Renderer::pixels() {
  finish();
  const auto* p = static_cast<const uint32_t*>(output_.mapped);
  return {p, p + size_t(options_.width) * options_.height};
}

}  // namespace iso::viewer
