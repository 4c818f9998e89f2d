// Operating-system file access for the format: read-only memory maps (iso/atomic_file.h writes).
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

}  // namespace iso::detail
