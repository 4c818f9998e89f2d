// Operating-system file access for the format: read-only memory maps and durable output files.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace iso::detail {

// A whole file mapped read-only. Empty files are not mapped (bytes() is empty).
class MappedFile {
 public:
  // Throws iso::FileError when the file cannot be opened, is not a regular file or cannot be
  // mapped.
  explicit MappedFile(const std::filesystem::path& path);
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  std::span<const std::byte> bytes() const { return {data_, size_}; }

 private:
  const std::byte* data_ = nullptr;
  size_t size_ = 0;
};

// A file written under a temporary name next to its final path and renamed into place by commit().
// Every error throws iso::FileError naming the final path.
class AtomicOutputFile {
 public:
  explicit AtomicOutputFile(std::filesystem::path path);
  ~AtomicOutputFile();  // removes the temporary file unless committed
  AtomicOutputFile(const AtomicOutputFile&) = delete;
  AtomicOutputFile& operator=(const AtomicOutputFile&) = delete;

  void write(std::span<const std::byte> bytes);
  void writeZeros(uint64_t count);
  // Cut the file to `size` bytes and continue writing there.
  void truncate(uint64_t size);
  uint64_t position() const { return position_; }

  // Flush to disk, rename over the final path, and flush the directory entry.
  void commit();
  // Close and remove the temporary file (no-op after commit).
  void discard() noexcept;

  const std::filesystem::path& path() const { return path_; }
  const std::filesystem::path& temporaryPath() const { return temporary_; }

 private:
  [[noreturn]] void fail(const std::string& what, int error) const;

  std::filesystem::path path_;
  std::filesystem::path temporary_;
  int fd_ = -1;
  uint64_t position_ = 0;
  bool committed_ = false;
};

}  // namespace iso::detail
