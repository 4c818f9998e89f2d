// The page pool's residency and the loader thread (streaming.h, specs/viewer.md "Streaming").
#include "viewer/streaming.h"

#include <algorithm>
#include <stdexcept>

#include "iso/error.h"
#include "iso/points.h"
#include "iso/surface.h"
#include "shaders/shared.h"

namespace iso::viewer {

ChunkCache::ChunkCache(const Reader& reader, const ChunkTree& tree, BlobOptions options,
                       uint32_t poolPages, uint32_t pagesPerBuffer, const SplatIndex* splats)
    : reader_(reader),
      tree_(tree),
      options_(options),
      splats_(splats),
      poolPages_(poolPages),
      pagesPerBuffer_(std::max<uint32_t>(pagesPerBuffer, 1)) {
  state_.resize(reader.chunks().size() + (splats ? 1 : 0));
  used_.assign(poolPages, 0);
  if (tree.topChunk() == kNoParent) throw std::runtime_error("the file has no surface chunk");
  std::vector<uint32_t> pinned{tree.topChunk()};
  if (splats) pinned.push_back(splats->chunk);
  uint64_t pages = 0;
  {
    std::lock_guard lock(mutex_);
    for (uint32_t chunk : pinned) {
      state_[chunk].queued = true;
      state_[chunk].pinned = true;
      ready_.emplace_back(chunk, prepare(chunk));
      pages += blobPages(ready_.back().second.size());
      if (blobPages(ready_.back().second.size()) > pagesPerBuffer_) pages = UINT64_MAX;
    }
  }
  if (pages > poolPages)
    throw std::runtime_error("--vram is too small: the coarsest chunk (and the splat index) alone "
                             "need more than the page pool's " +
                             std::to_string(uint64_t(poolPages) * gpu::kPageWords * 4) + " bytes");
  loader_ = std::thread([this] { loaderLoop(); });
}

ChunkCache::~ChunkCache() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  loader_.join();
}

std::vector<uint32_t> ChunkCache::prepare(uint32_t chunk) const {
  if (splats_ != nullptr && chunk == splats_->chunk) return splats_->words;
  if (reader_.chunk(chunk).kind == kPointsKind)
    return buildSplatBlob(decodePointsChunk(reader_, chunk), reader_.chunk(chunk));
  // Decoding checks the payload's checksum (once per load) and the table's node and leaf counts,
  // from which the renderer sizes buffers.
  const SurfaceChunk decoded = decodeBlobChunk(reader_, chunk, options_);
  return buildBlob(decoded, chunk, tree_, options_);
}

void ChunkCache::request(uint32_t chunk, uint64_t frame) {
  if (chunk >= state_.size()) return;
  State& s = state_[chunk];
  s.lastRequested = frame;
  if (s.firstPage != kNone || s.queued) return;
  s.queued = true;
  {
    std::lock_guard lock(mutex_);
    queue_.push_back(chunk);
  }
  wake_.notify_one();
}

void ChunkCache::use(uint32_t chunk, uint64_t frame) {
  if (chunk < state_.size()) state_[chunk].lastUsed = std::max(state_[chunk].lastUsed, frame);
}

void ChunkCache::loaderLoop() {
  for (;;) {
    uint32_t chunk;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stop_ || (!queue_.empty() && !error_); });
      if (stop_) return;
      // Coarser chunks first: they stand in for more of the picture.
      const auto level = [&](uint32_t c) {
        return c < reader_.chunks().size() ? reader_.chunk(c).level : uint8_t{0};
      };
      auto best = std::min_element(queue_.begin(), queue_.end(),
                                   [&](uint32_t a, uint32_t b) { return level(a) < level(b); });
      chunk = *best;
      queue_.erase(best);
      busy_ = true;
    }
    std::vector<uint32_t> blob;
    std::optional<std::string> failure;
    try {
      blob = prepare(chunk);
    } catch (const std::exception& e) {
      failure = e.what();
    }
    std::lock_guard lock(mutex_);
    busy_ = false;
    if (failure)
      error_ = failure;
    else
      ready_.emplace_back(chunk, std::move(blob));
  }
}

void ChunkCache::gpuProgress(uint64_t submitted, uint64_t completed) {
  submitted_ = submitted;
  completed_ = completed;
  releaseRetired();
}

void ChunkCache::releaseRetired() {
  while (!retired_.empty() && retired_.front().lastReader <= completed_) {
    const Retired& r = retired_.front();
    std::fill_n(used_.begin() + r.firstPage, r.pages, uint8_t{kFree});
    pagesInUse_ -= r.pages;
    retiredPages_ -= r.pages;
    retired_.pop_front();
  }
}

uint32_t ChunkCache::freeRun(uint32_t pages, bool retiredFree) const {
  uint32_t run = 0;
  for (uint32_t p = 0; p < poolPages_; ++p) {
    if (p % pagesPerBuffer_ == 0) run = 0;  // runs stay inside a buffer
    const bool free = used_[p] == kFree || (retiredFree && used_[p] == kRetired);
    run = free ? run + 1 : 0;
    if (run == pages) return p + 1 - pages;  // the lowest run that fits
  }
  return kNone;
}

uint32_t ChunkCache::makeRoom(uint32_t pages, uint64_t frame, std::vector<uint32_t>& evicted) {
  if (pages > std::min(poolPages_, pagesPerBuffer_)) return kNone;
  for (;;) {
    releaseRetired();
    const uint32_t first = freeRun(pages, false);
    if (first != kNone) return first;
    if (freeRun(pages, true) != kNone) return kNone;  // free once frames in flight complete
    uint32_t victim = kNone;
    for (uint32_t c = 0; c < state_.size(); ++c) {
      const State& s = state_[c];
      if (s.firstPage == kNone || s.pinned || s.lastUsed >= frame) continue;
      if (victim == kNone || s.lastUsed < state_[victim].lastUsed) victim = c;
    }
    if (victim == kNone) return kNone;
    State& s = state_[victim];
    std::fill_n(used_.begin() + s.firstPage, s.pages, uint8_t{kRetired});
    retired_.push_back({s.firstPage, s.pages, submitted_});
    retiredPages_ += s.pages;
    s.pages = 0;
    s.firstPage = kNone;
    --residentCount_;
    evicted.push_back(victim);
  }
}

std::vector<ChunkCache::Upload> ChunkCache::place(uint64_t frame, uint64_t maxBytes,
                                                  std::vector<uint32_t>& evicted) {
  std::vector<Upload> uploads;
  uint64_t bytes = 0;
  std::deque<std::pair<uint32_t, std::vector<uint32_t>>> ready;
  {
    std::lock_guard lock(mutex_);
    ready.swap(ready_);
  }
  std::deque<std::pair<uint32_t, std::vector<uint32_t>>> keep;
  while (!ready.empty()) {
    auto [chunk, words] = std::move(ready.front());
    ready.pop_front();
    State& s = state_[chunk];
    const uint32_t pages = blobPages(words.size());
    // Past this frame's upload budget, or a chunk no longer wanted: wait, or drop.
    const bool wanted = s.pinned || s.lastRequested + 8 >= frame;
    if (!wanted) {
      s.queued = false;
      continue;
    }
    const uint32_t first = (bytes > 0 && bytes + words.size() * 4 > maxBytes)
                               ? kNone
                               : makeRoom(pages, frame, evicted);
    if (first == kNone) {
      keep.emplace_back(chunk, std::move(words));
      continue;
    }
    Upload up;
    up.chunk = chunk;
    up.firstPage = first;
    std::fill_n(used_.begin() + first, pages, uint8_t{kResident});
    pagesInUse_ += pages;
    s.pages = pages;
    s.firstPage = first;
    s.queued = false;
    s.lastUsed = std::max(s.lastUsed, frame);
    ++residentCount_;
    bytes += words.size() * 4;
    up.words = std::move(words);
    uploads.push_back(std::move(up));
  }
  std::lock_guard lock(mutex_);
  for (auto& k : keep) ready_.push_back(std::move(k));
  return uploads;
}

uint32_t ChunkCache::pendingChunks() const {
  uint32_t n = 0;
  for (const State& s : state_) n += s.queued ? 1 : 0;
  return n;
}

bool ChunkCache::idle() const {
  std::lock_guard lock(mutex_);
  return queue_.empty() && !busy_;
}

std::optional<std::string> ChunkCache::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

}  // namespace iso::viewer
