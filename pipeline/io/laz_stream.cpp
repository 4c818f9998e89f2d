#include "pipeline/io/laz_stream.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include "iso/error.h"
#include "pipeline/io/laz_decoder.h"
#include "pipeline/io/little_endian.h"

namespace iso::io {
namespace {

// A chunk whose records take more than this is decoded by its reader, a slice at a time, rather
// than at once by the pool (LASzip's chunks of 50,000 points take 1–2 MiB).
constexpr size_t kPooledBytes = size_t{16} << 20;
constexpr size_t kLargeSliceRecords = 65536;
// Chunks a stream queues ahead of the one it reads.
constexpr size_t kQueuedAhead = 64;

size_t workerCount() { return std::clamp<size_t>(std::thread::hardware_concurrency(), 1, 32); }

}  // namespace

SharedFile::SharedFile(const std::filesystem::path& path) : name_(path.string()) {
  descriptor_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (descriptor_ < 0)
    throw FileError(name_, std::nullopt, fmt::format("cannot open: {}", std::strerror(errno)));
}

SharedFile::~SharedFile() { ::close(descriptor_); }

void SharedFile::read(uint64_t offset, size_t bytes, std::byte* to) const {
  size_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::pread(descriptor_, to + done, bytes - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0)
      throw FileError(name_, offset + done, fmt::format("cannot read: {}", std::strerror(errno)));
    if (n == 0)
      throw FileError(name_, offset + done,
                      fmt::format("file ends inside the {} bytes from byte {}", bytes, offset));
    done += size_t(n);
  }
}

// One chunk to decode, from the queue to the reader that takes it.
struct LazJob {
  enum class State : uint8_t { kQueued, kRunning, kDone, kTaken, kCancelled };
  std::pair<uint64_t, uint64_t> order;  // the stream's number, the chunk's
  std::shared_ptr<const SharedFile> file;
  LazChunk chunk;
  int format = 0;
  size_t recordLength = 0;
  State state = State::kQueued;
  std::vector<std::byte> records;
  std::optional<FileError> error;  // why it could not be decoded
};

namespace {

// Read a chunk's compressed bytes. A chunk of LAS 1.4 points (layered compression) starts with
// its first point, raw, and its number of points (u32), which must be the chunk table's.
std::vector<std::byte> readChunk(const SharedFile& file, const LazChunk& chunk, int format,
                                 size_t recordLength) {
  std::vector<std::byte> compressed(chunk.bytes);
  file.read(chunk.offset, compressed.size(), compressed.data());
  if (format >= 6 && chunk.points > 0) {
    const uint32_t count = compressed.size() >= recordLength + 4
                               ? loadLittleEndian<uint32_t>(compressed.data() + recordLength)
                               : 0;
    if (count != chunk.points)
      throw FileError(file.name(), chunk.offset,
                      fmt::format("the chunk says it holds {} points, the chunk table {}", count,
                                  chunk.points));
  }
  return compressed;
}

// Decode a job's chunk with the given decoder, keeping the records or the error in the job.
void decodeJob(LazJob& job, std::unique_ptr<LazChunkDecoder>& decoder) {
  try {
    const std::vector<std::byte> compressed =
        readChunk(*job.file, job.chunk, job.format, job.recordLength);
    if (!decoder) decoder = std::make_unique<LazChunkDecoder>();
    decoder->open(job.format, job.recordLength, compressed);
    job.records.resize(job.chunk.points * job.recordLength);
    decoder->decode(job.chunk.points, job.records.data());
  } catch (const FileError& error) {
    job.records = {};
    job.error = error;
  } catch (const std::exception& error) {  // LazDecodeError, std::bad_alloc
    job.records = {};
    job.error = FileError(job.file->name(), job.chunk.offset, error.what());
  }
}

// The workers and the queue they serve: the chunks of the stream made first, in order, then
// the next stream's (readers read their files in the order they opened them).
class Pool {
 public:
  static Pool& shared() {
    static Pool pool;
    return pool;
  }

  // A number for a new stream, larger than the ones before.
  uint64_t numberStream() {
    std::lock_guard lock(mutex_);
    ++liveStreams_;
    return streams_++;
  }

  // A stream is gone; when none is left, the decoders' memory goes too (a conversion reads its
  // inputs first, then needs the memory for other stages).
  void endStream() {
    {
      std::lock_guard lock(mutex_);
      if (--liveStreams_ > 0) return;
      spares_.clear();
    }
    workAvailable_.notify_all();
  }

  Pool(const Pool&) = delete;
  Pool& operator=(const Pool&) = delete;
  ~Pool() {
    {
      std::lock_guard lock(mutex_);
      isStopping_ = true;
    }
    workAvailable_.notify_all();
    for (std::thread& worker : workers_) worker.join();
  }

  void queue(const std::shared_ptr<LazJob>& job) {
    {
      std::lock_guard lock(mutex_);
      if (workers_.empty())
        for (size_t i = 0; i < workerCount(); ++i) workers_.emplace_back([this] { work(); });
      queue_.emplace(job->order, job);
    }
    workAvailable_.notify_one();
  }

  // Wait for the job's records, decoding it here when no worker has started it.
  void take(LazJob& job) {
    std::unique_lock lock(mutex_);
    if (job.state == LazJob::State::kQueued) {
      queue_.erase(job.order);
      job.state = LazJob::State::kRunning;
      std::unique_ptr<LazChunkDecoder> decoder;
      if (!spares_.empty()) {
        decoder = std::move(spares_.back());
        spares_.pop_back();
      }
      lock.unlock();
      decodeJob(job, decoder);
      lock.lock();
      if (decoder && liveStreams_ > 0) spares_.push_back(std::move(decoder));
    } else {
      jobDone_.wait(lock, [&] { return job.state == LazJob::State::kDone; });
      --outstanding_;
      workAvailable_.notify_one();
    }
    job.state = LazJob::State::kTaken;
  }

  void cancel(LazJob& job) {
    std::lock_guard lock(mutex_);
    switch (job.state) {
      case LazJob::State::kQueued:
        queue_.erase(job.order);
        break;
      case LazJob::State::kDone:
        --outstanding_;
        workAvailable_.notify_one();
        break;
      case LazJob::State::kRunning:  // the worker drops it when it is done
      case LazJob::State::kTaken:
      case LazJob::State::kCancelled:
        break;
    }
    if (job.state != LazJob::State::kTaken) job.state = LazJob::State::kCancelled;
  }

 private:
  Pool() = default;

  // Decoded and not yet taken, or being decoded: at most this many (memory: kPooledBytes each).
  size_t window() const { return 2 * workers_.size() + 2; }

  void work() {
    std::unique_ptr<LazChunkDecoder> decoder;
    std::unique_lock lock(mutex_);
    for (;;) {
      workAvailable_.wait(lock, [&] {
        return isStopping_ || (!queue_.empty() && outstanding_ < window()) ||
               (decoder && liveStreams_ == 0);
      });
      if (isStopping_) return;
      if (liveStreams_ == 0) {
        decoder.reset();
        continue;
      }
      const std::shared_ptr<LazJob> job = queue_.begin()->second;
      queue_.erase(queue_.begin());
      job->state = LazJob::State::kRunning;
      ++outstanding_;
      lock.unlock();
      decodeJob(*job, decoder);
      lock.lock();
      if (job->state == LazJob::State::kCancelled) {
        --outstanding_;
        job->records = {};
        continue;
      }
      job->state = LazJob::State::kDone;
      jobDone_.notify_all();
    }
  }

  std::mutex mutex_;
  std::condition_variable workAvailable_, jobDone_;
  std::map<std::pair<uint64_t, uint64_t>, std::shared_ptr<LazJob>> queue_;
  size_t outstanding_ = 0;
  std::vector<std::thread> workers_;
  uint64_t streams_ = 0, liveStreams_ = 0;
  std::vector<std::unique_ptr<LazChunkDecoder>> spares_;  // for readers that decode themselves
  bool isStopping_ = false;
};

}  // namespace

// A chunk decoded by its reader a slice at a time.
struct LazChunkStream::LargeChunk {
  std::unique_ptr<LazChunkDecoder> decoder;
  uint64_t remaining = 0;
  std::vector<std::byte> records;
};

LazChunkStream::LazChunkStream(std::shared_ptr<const SharedFile> file, int format,
                               size_t recordLength, std::vector<LazChunk> chunks)
    : file_(std::move(file)),
      format_(format),
      recordLength_(recordLength),
      chunks_(std::move(chunks)),
      number_(Pool::shared().numberStream()) {
  queueAhead();
}

LazChunkStream::~LazChunkStream() {
  for (const std::shared_ptr<LazJob>& job : jobs_)
    if (job) Pool::shared().cancel(*job);
  Pool::shared().endStream();
}

void LazChunkStream::queueAhead() {
  for (; nextQueued_ < chunks_.size() && nextQueued_ < nextChunk_ + kQueuedAhead; ++nextQueued_) {
    const LazChunk& chunk = chunks_[nextQueued_];
    if (chunk.points * recordLength_ > kPooledBytes) {
      jobs_.push_back(nullptr);
      continue;
    }
    auto job = std::make_shared<LazJob>();
    job->order = {number_, nextQueued_};
    job->file = file_;
    job->chunk = chunk;
    job->format = format_;
    job->recordLength = recordLength_;
    jobs_.push_back(job);
    Pool::shared().queue(job);
  }
}

std::span<const std::byte> LazChunkStream::next(size_t maxRecords) {
  for (;;) {
    if (large_) return fromLargeChunk(maxRecords);
    if (current_) {
      const size_t records = current_->records.size() / recordLength_;
      if (recordsTaken_ < records) {
        const size_t count = std::min(maxRecords, records - recordsTaken_);
        const std::span<const std::byte> out(
            current_->records.data() + recordsTaken_ * recordLength_, count * recordLength_);
        recordsTaken_ += count;
        return out;
      }
      current_.reset();
    }
    if (nextChunk_ == chunks_.size()) return {};
    std::shared_ptr<LazJob> job = std::move(jobs_.front());
    jobs_.pop_front();
    const LazChunk& chunk = chunks_[nextChunk_++];
    queueAhead();
    if (!job) {
      large_ = std::make_unique<LargeChunk>();
      try {
        const std::vector<std::byte> compressed = readChunk(*file_, chunk, format_, recordLength_);
        large_->decoder = std::make_unique<LazChunkDecoder>();
        large_->decoder->open(format_, recordLength_, compressed);
      } catch (const LazDecodeError& error) {
        throw FileError(
            file_->name(), chunk.offset,
            fmt::format("chunk {} of {}: {}", nextChunk_, chunks_.size(), error.what()));
      }
      large_->remaining = chunk.points;
      continue;
    }
    Pool::shared().take(*job);
    if (job->error)
      throw FileError(
          job->error->file(), job->error->offset(),
          fmt::format("chunk {} of {}: {}", nextChunk_, chunks_.size(), job->error->reason()));
    current_ = std::move(job);
    recordsTaken_ = 0;
  }
}

std::span<const std::byte> LazChunkStream::fromLargeChunk(size_t maxRecords) {
  const size_t count =
      size_t(std::min<uint64_t>({large_->remaining, maxRecords, kLargeSliceRecords}));
  if (count == 0) {
    large_.reset();
    return next(maxRecords);
  }
  large_->records.resize(count * recordLength_);
  try {
    large_->decoder->decode(count, large_->records.data());
  } catch (const LazDecodeError& error) {
    const LazChunk& chunk = chunks_[nextChunk_ - 1];
    throw FileError(file_->name(), chunk.offset,
                    fmt::format("chunk {} of {}: {}", nextChunk_, chunks_.size(), error.what()));
  }
  large_->remaining -= count;
  return large_->records;
}

}  // namespace iso::io
