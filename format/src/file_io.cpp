#include "file_io.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "iso/error.h"

namespace iso::detail {
namespace {

std::string errorText(int error) { return std::strerror(error); }

// Close fd, retrying nothing: on Linux the descriptor is released even when close() fails.
void closeQuietly(int fd) {
  if (fd >= 0) ::close(fd);
}

}  // namespace

MappedFile::MappedFile(const std::filesystem::path& path) {
  const std::string name = path.string();
  const int fd = ::open(name.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw FileError(name, std::nullopt, "cannot open: " + errorText(errno));
  struct stat info {};
  if (::fstat(fd, &info) != 0) {
    const int error = errno;
    closeQuietly(fd);
    throw FileError(name, std::nullopt, "cannot stat: " + errorText(error));
  }
  if (!S_ISREG(info.st_mode)) {
    closeQuietly(fd);
    throw FileError(name, std::nullopt, "not a regular file");
  }
  size_ = static_cast<size_t>(info.st_size);
  if (size_ > 0) {
    void* map = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (map == MAP_FAILED) {
      const int error = errno;
      closeQuietly(fd);
      throw FileError(name, std::nullopt, "cannot map into memory: " + errorText(error));
    }
    data_ = static_cast<const std::byte*>(map);
  }
  closeQuietly(fd);  // the mapping keeps the file alive
}

MappedFile::~MappedFile() {
  if (data_ != nullptr) ::munmap(const_cast<std::byte*>(data_), size_);
}

}  // namespace iso::detail
