#include "pipeline/io/input_stream.h"

#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstring>
#include <limits>
#include <utility>

#include "iso/error.h"

namespace iso::io {
namespace {

// Reads into the buffer are mostly larger than zlib's own buffer, so that zlib copies plain files
// straight into it rather than through its buffer.
constexpr size_t kInitialCapacity = size_t{4} << 20;
constexpr unsigned kZlibBufferSize = 256u << 10;
constexpr size_t kMaxLineLength = size_t{16} << 20;

gzFile asGz(void* file) { return static_cast<gzFile>(file); }

}  // namespace

InputStream::InputStream(const std::filesystem::path& path) : path_(path), name_(path.string()) {
  std::error_code error;
  if (std::filesystem::is_directory(path, error))
    throw FileError(name_, std::nullopt, "is a directory, not a file");
  errno = 0;
  gzFile file = gzopen(name_.c_str(), "rb");
  if (file == nullptr) {
    const std::string why = errno != 0 ? std::strerror(errno) : "out of memory";
    throw FileError(name_, std::nullopt, "cannot open: " + why);
  }
  file_ = file;
  gzbuffer(file, kZlibBufferSize);  // must be set before the first read
  buffer_ = std::make_unique_for_overwrite<std::byte[]>(kInitialCapacity);
  capacity_ = kInitialCapacity;
  // A plain file's offsets are the stream's, so its size bounds what headers may claim.
  if (gzdirect(file) == 1) {
    const uintmax_t size = std::filesystem::file_size(path, error);
    if (!error) knownSize_ = size;
  }
}

InputStream::~InputStream() {
  if (file_ != nullptr) gzclose(asGz(file_));
}

InputStream::InputStream(InputStream&& other) noexcept
    : path_(std::move(other.path_)),
      name_(std::move(other.name_)),
      file_(std::exchange(other.file_, nullptr)),
      buffer_(std::move(other.buffer_)),
      capacity_(std::exchange(other.capacity_, 0)),
      begin_(std::exchange(other.begin_, 0)),
      end_(std::exchange(other.end_, 0)),
      base_(other.base_),
      lineNumber_(other.lineNumber_),
      isAtEnd_(other.isAtEnd_),
      knownSize_(other.knownSize_) {}

void InputStream::failAt(uint64_t offset, const std::string& reason) const {
  throw FileError(name_, offset, reason);
}

void InputStream::failLine(const std::string& reason) const {
  throw FileError(name_, std::nullopt, "line " + std::to_string(lineNumber_) + ": " + reason);
}

std::span<const std::byte> InputStream::refill(size_t n) {
  if (!isAtEnd_) fillBuffer(std::max(n, capacity_));
  return {buffer_.get() + begin_, end_ - begin_};
}

void InputStream::fillBuffer(size_t capacity) {
  if (begin_ > 0) {
    std::memmove(buffer_.get(), buffer_.get() + begin_, end_ - begin_);
    base_ += begin_;
    end_ -= begin_;
    begin_ = 0;
  }
  if (capacity > capacity_) {
    const size_t grown = std::max(capacity, capacity_ * 2);
    auto buffer = std::make_unique_for_overwrite<std::byte[]>(grown);
    std::memcpy(buffer.get(), buffer_.get(), end_);
    buffer_ = std::move(buffer);
    capacity_ = grown;
  }
  gzFile file = asGz(file_);
  while (end_ < capacity_ && !isAtEnd_) {
    const auto request = static_cast<unsigned>(std::min<size_t>(capacity_ - end_, INT_MAX));
    const int got = gzread(file, buffer_.get() + end_, request);
    int status = Z_OK;
    const char* message = gzerror(file, &status);
    if (got < 0) failAt(base_ + end_, std::string("cannot read: ") + message);
    end_ += static_cast<size_t>(got);
    if (got > 0) continue;
    // zlib reports a gzip stream cut short as a plain end of file, with this status.
    if (status == Z_BUF_ERROR)
      failAt(base_ + end_, "the compressed data ends unexpectedly (truncated .gz file)");
    isAtEnd_ = true;
  }
}

uint64_t InputStream::skip(uint64_t n) {
  uint64_t skipped = 0;
  while (skipped < n) {
    const std::span<const std::byte> available = peek(1);
    if (available.empty()) break;
    const size_t take = static_cast<size_t>(std::min<uint64_t>(available.size(), n - skipped));
    consume(take);
    skipped += take;
  }
  return skipped;
}

void InputStream::seek(uint64_t offset) {
  if (offset >= base_ && offset <= base_ + end_) {
    begin_ = static_cast<size_t>(offset - base_);
    return;
  }
  errno = 0;
  if (offset > uint64_t(std::numeric_limits<z_off_t>::max()) ||
      gzseek(asGz(file_), static_cast<z_off_t>(offset), SEEK_SET) < 0) {
    int status = Z_OK;
    const char* message = gzerror(asGz(file_), &status);
    failAt(offset,
           std::string("cannot seek: ") + (status != Z_OK ? message : std::strerror(errno)));
  }
  base_ = offset;
  begin_ = end_ = 0;
  isAtEnd_ = false;
}

bool InputStream::readExact(void* destination, size_t n) {
  auto* out = static_cast<std::byte*>(destination);
  while (n > 0) {
    const std::span<const std::byte> available = peek(1);
    if (available.empty()) return false;
    const size_t take = std::min(available.size(), n);
    std::memcpy(out, available.data(), take);
    consume(take);
    out += take;
    n -= take;
  }
  return true;
}

bool InputStream::readLine(std::string_view& line) {
  size_t searched = 0;  // bytes after begin_ known to hold no newline
  for (;;) {
    const char* start = reinterpret_cast<const char*>(buffer_.get() + begin_);
    const size_t available = end_ - begin_;
    const void* newline = std::memchr(start + searched, '\n', available - searched);
    if (newline != nullptr || (isAtEnd_ && available > 0)) {
      const size_t length = newline != nullptr
                                ? static_cast<size_t>(static_cast<const char*>(newline) - start)
                                : available;
      line = {start, length};
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      begin_ += std::min(length + 1, available);
      ++lineNumber_;
      return true;
    }
    if (isAtEnd_) return false;
    if (available >= kMaxLineLength) {
      ++lineNumber_;
      failLine("line longer than 16 MiB (is this a text file?)");
    }
    searched = available;
    fillBuffer(available == capacity_ ? capacity_ * 2 : capacity_);
  }
}

}  // namespace iso::io
