// The records of a LAZ file's chunks, in order, decoded ahead of the reader by a process-wide
// pool of worker threads (one a core, each with its own laz-perf decoder). Chunks are queued in
// the order readers ask for them, across files, and decoded first come first served within a
// bounded number decoded ahead; a reader that needs a chunk no worker has started decodes it
// itself. So the chunks of one large file, and the small files of a tiled scan opened together,
// both keep every core busy, while memory stays bounded.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "pipeline/io/laz_chunks.h"

namespace iso::io {

// A file read at any offset, from several threads.
class SharedFile {
 public:
  // Throws FileError when the file cannot be opened.
  explicit SharedFile(const std::filesystem::path& path);
  ~SharedFile();
  SharedFile(const SharedFile&) = delete;
  SharedFile& operator=(const SharedFile&) = delete;
  const std::string& name() const { return name_; }
  // Read `bytes` bytes at `offset` into `to`; throws FileError when the file ends first.
  void read(uint64_t offset, size_t bytes, std::byte* to) const;

 private:
  std::string name_;
  int descriptor_ = -1;
};

struct LazJob;

class LazChunkStream {
 public:
  LazChunkStream(std::shared_ptr<const SharedFile> file, int format, size_t recordLength,
                 std::vector<LazChunk> chunks);
  // Cancels the chunks queued for it that it did not take.
  ~LazChunkStream();
  LazChunkStream(const LazChunkStream&) = delete;
  LazChunkStream& operator=(const LazChunkStream&) = delete;

  // The next records (at most maxRecords, recordLength bytes each), empty after the last chunk;
  // valid until the next call. Throws FileError naming the chunk when it cannot be decoded.
  std::span<const std::byte> next(size_t maxRecords);

 private:
  void queueAhead();
  std::span<const std::byte> fromLargeChunk(size_t maxRecords);

  std::shared_ptr<const SharedFile> file_;
  int format_;
  size_t recordLength_;
  std::vector<LazChunk> chunks_;
  uint64_t number_;                           // in the pool's order of streams
  size_t nextChunk_ = 0;                      // the chunk next() continues with
  size_t nextQueued_ = 0;                     // the first chunk not queued yet
  std::deque<std::shared_ptr<LazJob>> jobs_;  // chunks nextChunk_ to nextQueued_ (null: large)
  std::shared_ptr<LazJob> current_;           // the chunk records come from
  size_t recordsTaken_ = 0;                   // of current_'s
  struct LargeChunk;
  std::unique_ptr<LargeChunk> large_;  // a chunk too large to decode at once
};

}  // namespace iso::io
