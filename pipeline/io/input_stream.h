// Buffered input of a plain or gzip-compressed file (zlib reads both transparently), for the
// readers: zero-copy access to the buffer for block decoding, fast line reading for text, and the
// offset in the uncompressed stream for error messages. Used by one thread at a time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace iso::io {

class InputStream {
 public:
  // Throws iso::FileError when the file cannot be opened or is a directory.
  explicit InputStream(const std::filesystem::path& path);
  ~InputStream();
  InputStream(InputStream&& other) noexcept;
  InputStream& operator=(InputStream&&) = delete;
  InputStream(const InputStream&) = delete;
  InputStream& operator=(const InputStream&) = delete;

  const std::filesystem::path& path() const { return path_; }
  const std::string& name() const { return name_; }

  // Offset of the next unread byte in the uncompressed stream.
  uint64_t offset() const { return base_ + begin_; }
  // Size of the uncompressed stream when known without reading it (plain files), else nullopt.
  std::optional<uint64_t> knownSize() const { return knownSize_; }

  // All buffered unread bytes, at least n of them unless the file ends first. The view is valid
  // until the next non-const call.
  std::span<const std::byte> peek(size_t n) {
    if (end_ - begin_ >= n) return {buffer_.get() + begin_, end_ - begin_};
    return refill(n);
  }
  // Mark n peeked bytes as read.
  void consume(size_t n) { begin_ += n; }
  // Read and drop n bytes; returns how many there were (fewer only at the end of the file).
  uint64_t skip(uint64_t n);
  // Continue at the given offset of the uncompressed stream: plain files seek, gzip streams
  // decompress up to it (a reader past the end then finds no bytes there).
  void seek(uint64_t offset);
  // Copy the next n bytes to destination; false (having read what there was) if the file ends.
  bool readExact(void* destination, size_t n);

  // The next line without its terminator ("\n" or "\r\n"); false at the end of the file. The view
  // is valid until the next non-const call. Throws iso::FileError for lines over 16 MiB.
  bool readLine(std::string_view& line);
  // 1-based number of the line readLine() returned last (counting only lines read with it).
  uint64_t lineNumber() const { return lineNumber_; }

  // Throw iso::FileError for this file at the given offset, or at offset().
  [[noreturn]] void failAt(uint64_t offset, const std::string& reason) const;
  [[noreturn]] void fail(const std::string& reason) const { failAt(offset(), reason); }
  // Throw iso::FileError for this file with the reason prefixed by "line N: ".
  [[noreturn]] void failLine(const std::string& reason) const;

 private:
  std::span<const std::byte> refill(size_t n);
  // Move unread bytes to the front, grow the buffer to hold at least `capacity` bytes, then read
  // until it is full or the file ends.
  void fillBuffer(size_t capacity);

  std::filesystem::path path_;
  std::string name_;
  void* file_ = nullptr;  // gzFile
  std::unique_ptr<std::byte[]> buffer_;
  size_t capacity_ = 0;
  size_t begin_ = 0;   // first unread byte in buffer_
  size_t end_ = 0;     // one past the last buffered byte
  uint64_t base_ = 0;  // stream offset of buffer_[0]
  uint64_t lineNumber_ = 0;
  bool isAtEnd_ = false;  // the file has no bytes beyond end_
  std::optional<uint64_t> knownSize_;
};

}  // namespace iso::io
