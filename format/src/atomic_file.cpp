#include "iso/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <string>

#include "iso/error.h"

namespace iso {
namespace {

constexpr size_t kBufferSize = size_t{1} << 20;

// A name that no concurrent writer in this or another process uses: ".NAME.PID-SEQUENCE.isotmp" in
// the final path's directory (the same file system, so the rename is atomic).
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

AtomicFile::AtomicFile(std::filesystem::path path)
    : path_(std::move(path)),
      temporary_(temporaryPathFor(path_)),
      buffer_(new std::byte[kBufferSize]) {
  if (path_.filename().empty()) fail("invalid output path", EISDIR);
  // Registered before it exists: an interrupt between the two would otherwise leave it behind.
  registration_ = TemporaryRegistration(temporary_);
  fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0) fail("cannot create " + temporary_.string(), errno);
}

AtomicFile::~AtomicFile() { discard(); }

void AtomicFile::fail(const std::string& what, int error) const {
  throw FileError(path_.string(), std::nullopt, what + ": " + std::strerror(error));
}

void AtomicFile::writeDirect(std::span<const std::byte> bytes) {
  if (fd_ < 0) fail("write after the file was closed", EBADF);
  while (!bytes.empty()) {
    const ssize_t written = ::write(fd_, bytes.data(), bytes.size());
    if (written < 0 && errno == EINTR) continue;
    if (written <= 0)
      fail("cannot write at byte " + std::to_string(flushed_), written < 0 ? errno : EIO);
    bytes = bytes.subspan(size_t(written));
    flushed_ += uint64_t(written);
  }
}

void AtomicFile::flush() {
  const size_t pending = buffered_;
  buffered_ = 0;
  if (pending > 0) writeDirect({buffer_.get(), pending});
}

void AtomicFile::write(std::span<const std::byte> bytes) {
  position_ += bytes.size();
  if (buffered_ + bytes.size() <= kBufferSize) {
    if (!bytes.empty()) std::memcpy(buffer_.get() + buffered_, bytes.data(), bytes.size());
    buffered_ += bytes.size();
    return;
  }
  const size_t pending = buffered_;
  buffered_ = 0;
  if (pending > 0) writeDirect({buffer_.get(), pending});
  writeDirect(bytes);
}

void AtomicFile::writeZeros(uint64_t count) {
  static const std::array<std::byte, 65536> zeros{};
  while (count > 0) {
    const size_t n = count < zeros.size() ? size_t(count) : zeros.size();
    write({zeros.data(), n});
    count -= n;
  }
}

void AtomicFile::truncate(uint64_t size) {
  flush();
  if (::ftruncate(fd_, off_t(size)) != 0) fail("cannot truncate", errno);
  if (::lseek(fd_, off_t(size), SEEK_SET) < 0) fail("cannot seek", errno);
  position_ = flushed_ = size;
}

void AtomicFile::commit() {
  flush();
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
  registration_ = TemporaryRegistration();
  // Make the rename durable; a failure here leaves a complete file, so it is not an error.
  const std::filesystem::path directory = path_.has_parent_path() ? path_.parent_path() : ".";
  const int dirFd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dirFd >= 0) {
    ::fsync(dirFd);
    ::close(dirFd);
  }
}

void AtomicFile::discard() noexcept {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  if (!committed_ && !temporary_.empty()) {
    ::unlink(temporary_.c_str());
    temporary_.clear();
  }
  registration_ = TemporaryRegistration();
}

}  // namespace iso
