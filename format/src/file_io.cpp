#include "file_io.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
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

// A name for the temporary file that no concurrent writer in this or another process uses:
// ".NAME.PID-SEQUENCE.isotmp" in the output's directory (same file system, so rename is atomic).
std::filesystem::path temporaryPathFor(const std::filesystem::path& path) {
  static std::atomic<uint64_t> sequence{0};
  std::string name = ".";
  name += path.filename().string();
  name += '.';
  name += std::to_string(::getpid());
  name += '-';
  name += std::to_string(sequence++);
  name += ".isotmp";
  return path.parent_path() / name;
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

AtomicOutputFile::AtomicOutputFile(std::filesystem::path path)
    : path_(std::move(path)), temporary_(temporaryPathFor(path_)) {
  if (path_.filename().empty()) fail("invalid output path", EISDIR);
  fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0) fail("cannot create " + temporary_.string(), errno);
}

AtomicOutputFile::~AtomicOutputFile() { discard(); }

void AtomicOutputFile::fail(const std::string& what, int error) const {
  throw FileError(path_.string(), std::nullopt, what + ": " + errorText(error));
}

void AtomicOutputFile::write(std::span<const std::byte> bytes) {
  if (fd_ < 0) fail("write after the file was closed", EBADF);
  while (!bytes.empty()) {
    const ssize_t written = ::write(fd_, bytes.data(), bytes.size());
    if (written < 0) {
      if (errno == EINTR) continue;
      fail("cannot write at byte " + std::to_string(position_), errno);
    }
    if (written == 0) fail("cannot write at byte " + std::to_string(position_), EIO);
    bytes = bytes.subspan(static_cast<size_t>(written));
    position_ += static_cast<uint64_t>(written);
  }
}

void AtomicOutputFile::writeZeros(uint64_t count) {
  static const std::array<std::byte, 65536> zeros{};
  while (count > 0) {
    const size_t n = count < zeros.size() ? static_cast<size_t>(count) : zeros.size();
    write({zeros.data(), n});
    count -= n;
  }
}

void AtomicOutputFile::truncate(uint64_t size) {
  if (fd_ < 0) fail("truncate after the file was closed", EBADF);
  if (::ftruncate(fd_, off_t(size)) != 0) fail("cannot truncate", errno);
  if (::lseek(fd_, off_t(size), SEEK_SET) < 0) fail("cannot seek", errno);
  position_ = size;
}

void AtomicOutputFile::commit() {
  if (fd_ < 0) fail("commit after the file was closed", EBADF);
  if (::fsync(fd_) != 0) fail("cannot flush to disk", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    const int error = errno;
    ::unlink(temporary_.c_str());
    fail("cannot close", error);
  }
  if (::rename(temporary_.c_str(), path_.c_str()) != 0) {
    const int error = errno;
    ::unlink(temporary_.c_str());
    fail("cannot rename " + temporary_.string() + " to the output path", error);
  }
  committed_ = true;
  // Make the rename itself durable; a failure here leaves a complete file, so it is not an error.
  const std::filesystem::path directory = path_.has_parent_path() ? path_.parent_path() : ".";
  const int dirFd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dirFd >= 0) {
    ::fsync(dirFd);
    closeQuietly(dirFd);
  }
}

void AtomicOutputFile::discard() noexcept {
  if (fd_ >= 0) {
    closeQuietly(fd_);
    fd_ = -1;
  }
  if (!committed_ && !temporary_.empty()) {
    ::unlink(temporary_.c_str());
    temporary_.clear();
  }
}

}  // namespace iso::detail
