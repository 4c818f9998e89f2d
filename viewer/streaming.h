// Which chunks live in the GPU's page pool: an allocator of runs of consecutive pages (a chunk's
// blob is contiguous, in one pool buffer) with an LRU over chunks, and a
// loader thread that decodes requested chunks from the memory-mapped file into blobs (blob.h)
// while frames go on. No Vulkan here: the renderer uploads what place() hands out.
//
// Threading: every member function is called from one thread (the renderer's); the loader thread
// only touches the request and ready queues, under the mutex.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "iso/reader.h"
#include "tracer/blob.h"
#include "tracer/splats.h"

namespace iso::viewer {

class ChunkCache {
 public:
  // A pool of poolPages pages in buffers of pagesPerBuffer pages (a run never crosses from one to
  // the next). Throws when the top chunk alone does not fit.
  // With `splats`, points chunks are splat blobs and the splat index is one more chunk (number
  // splats->chunk), pinned like the top chunk.
  ChunkCache(const Reader& reader, const ChunkTree& tree, BlobOptions options, uint32_t poolPages,
             uint32_t pagesPerBuffer, const SplatIndex* splats = nullptr);
  ~ChunkCache();
  ChunkCache(const ChunkCache&) = delete;
  ChunkCache& operator=(const ChunkCache&) = delete;

  // A chunk's blob, decoded and built now on the calling thread.
  std::vector<uint32_t> prepare(uint32_t chunk) const;

  // A ray asked for the chunk in `frame` / went through it in `frame`.
  void request(uint32_t chunk, uint64_t frame);
  void use(uint32_t chunk, uint64_t frame);

  struct Upload {
    uint32_t chunk = 0;
    uint32_t firstPage = 0;       // the blob's pages are firstPage, firstPage + 1, ...
    std::vector<uint32_t> words;  // the blob
  };
  // Place prepared chunks into the pool, up to about maxBytes of them, evicting the least
  // recently used chunks that no ray used in `frame` (the last one with feedback) and that are not
  // pinned. `evicted` receives the chunks that left. The top chunk is placed, pinned, first.
  std::vector<Upload> place(uint64_t frame, uint64_t maxBytes, std::vector<uint32_t>& evicted);

  // The GPU's progress, told before place(): frames up to `submitted` were given chunk tables and
  // may read the pool; those up to `completed` are done. The pages of a chunk evicted now are
  // reused only once every frame submitted before its eviction has completed (frames in flight
  // read the pages their tables name). Without this call (both 0), pages are reused at once.
  void gpuProgress(uint64_t submitted, uint64_t completed);
  // Pages of evicted chunks that frames in flight may still read.
  uint32_t retiredPages() const { return retiredPages_; }

  bool resident(uint32_t chunk) const { return state_[chunk].firstPage != kNone; }
  uint32_t firstPage(uint32_t chunk) const { return state_[chunk].firstPage; }
  uint32_t residentChunks() const { return residentCount_; }
  // Pages resident or retired (waiting for frames in flight).
  uint32_t pagesInUse() const { return pagesInUse_; }
  uint32_t poolPages() const { return poolPages_; }
  // Chunks asked for and not resident (queued, being decoded, or decoded and waiting for room).
  uint32_t pendingChunks() const;
  // Whether the loader has nothing to do and nothing waits to be placed that could be.
  bool idle() const;
  // The first error of the loader thread (a corrupt chunk), if any.
  std::optional<std::string> error() const;

 private:
  static constexpr uint32_t kNone = 0xFFFFFFFFu;
  struct State {
    uint32_t firstPage = kNone;
    uint32_t pages = 0;
    uint64_t lastUsed = 0;
    uint64_t lastRequested = 0;
    bool queued = false;  // asked of the loader, not yet resident
    bool pinned = false;
  };
  void loaderLoop();
  // A free run of `pages` pages in one buffer, evicting the least recently used chunks that no
  // ray used in `frame` until one is free, or until one would be once frames in flight complete
  // (then kNone: the chunk is placed in a later frame); kNone also when no eviction can make one.
  uint32_t makeRoom(uint32_t pages, uint64_t frame, std::vector<uint32_t>& evicted);
  // The lowest run of `pages` free pages in one buffer (retired pages counted as free when
  // `retiredFree`), or kNone.
  uint32_t freeRun(uint32_t pages, bool retiredFree) const;
  void releaseRetired();

  const Reader& reader_;
  const ChunkTree& tree_;
  BlobOptions options_;
  const SplatIndex* splats_;
  uint32_t poolPages_, pagesPerBuffer_;
  enum : uint8_t { kFree, kResident, kRetired };
  std::vector<uint8_t> used_;  // per pool page
  uint32_t pagesInUse_ = 0, retiredPages_ = 0;
  struct Retired {
    uint32_t firstPage, pages;
    uint64_t lastReader;  // the last frame that may read them
  };
  std::deque<Retired> retired_;  // in eviction order, so lastReader never decreases
  uint64_t submitted_ = 0, completed_ = 0;
  std::vector<State> state_;
  uint32_t residentCount_ = 0;

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::vector<uint32_t> queue_;  // asked for, not yet taken by the loader
  std::deque<std::pair<uint32_t, std::vector<uint32_t>>> ready_;  // decoded, waiting for room
  bool busy_ = false;
  bool stop_ = false;
  std::optional<std::string> error_;
  std::thread loader_;
};

}  // namespace iso::viewer
