// A file written under a temporary name next to its final path and renamed into place by commit(),
// so that the final path holds either what it held before or a complete file, never a partial one.
// Small writes are buffered.
//
// Threading: one object is used by one thread at a time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string_view>

#include "iso/temporary_files.h"

namespace iso {

class AtomicFile {
 public:
  // Create the temporary file ".NAME.PID-N.isotmp" in the final path's directory. Every error of
  // this class throws iso::FileError naming the final path.
  explicit AtomicFile(std::filesystem::path path);
  ~AtomicFile();  // removes the temporary file unless committed
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(std::span<const std::byte> bytes);
  void write(std::string_view text) { write(std::as_bytes(std::span(text.data(), text.size()))); }
  void writeZeros(uint64_t count);
  uint64_t position() const { return position_; }
  // Cut the file to `size` bytes and continue writing there.
  void truncate(uint64_t size);
  // Hand the buffered bytes to the operating system: readers of temporaryPath() then see them.
  void flush();

  // Flush to disk, rename over the final path, and flush the directory entry.
  void commit();
  // Close and remove the temporary file (nothing happens after commit).
  void discard() noexcept;

  const std::filesystem::path& path() const { return path_; }
  const std::filesystem::path& temporaryPath() const { return temporary_; }

 private:
  void writeDirect(std::span<const std::byte> bytes);
  [[noreturn]] void fail(const std::string& what, int error) const;

  std::filesystem::path path_;
  std::filesystem::path temporary_;
  TemporaryRegistration registration_;  // of temporary_: removed on Ctrl-C too
  int fd_ = -1;
  uint64_t position_ = 0;  // bytes written, buffered ones included
  uint64_t flushed_ = 0;   // bytes handed to the operating system
  std::unique_ptr<std::byte[]> buffer_;
  size_t buffered_ = 0;
  bool committed_ = false;
};

}  // namespace iso
