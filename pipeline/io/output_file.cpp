#include "io/output_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <string>

#include "iso/error.h"

namespace iso::io {
namespace {

constexpr size_t kBufferSize = size_t{1} << 20;

// ".NAME.PID-SEQUENCE.tmp" beside the output: unique among concurrent writers, and on the same file
// system so that rename() is atomic.
std::filesystem::path temporaryPathFor(const std::filesystem::path& path) {
  static std::atomic<uint64_t> sequence{0};
  const std::string name = "." + path.filename().string() + "." + std::to_string(::getpid()) + "-" +
                           std::to_string(sequence++) + ".tmp";
  return path.parent_path() / name;
}

}  // namespace

OutputFile::OutputFile(std::filesystem::path path)
    : path_(std::move(path)),
      temporary_(temporaryPathFor(path_)),
      buffer_(std::make_unique_for_overwrite<std::byte[]>(kBufferSize)) {
  if (path_.filename().empty()) fail("invalid output path", EISDIR);
  fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0) fail("cannot create " + temporary_.string(), errno);
}

OutputFile::~OutputFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!isCommitted_) ::unlink(temporary_.c_str());
}

void OutputFile::fail(const std::string& what, int error) const {
  throw FileError(path_.string(), std::nullopt, what + ": " + std::strerror(error));
}

void OutputFile::write(std::span<const std::byte> bytes) {
  while (!bytes.empty()) {
    if (buffered_ == kBufferSize) flush();
    const size_t take = std::min(bytes.size(), kBufferSize - buffered_);
    std::memcpy(buffer_.get() + buffered_, bytes.data(), take);
    buffered_ += take;
    bytes = bytes.subspan(take);
  }
}

void OutputFile::flush() {
  const std::byte* data = buffer_.get();
  size_t left = buffered_;
  while (left > 0) {
    const ssize_t written = ::write(fd_, data, left);
    if (written < 0 && errno == EINTR) continue;
    if (written <= 0) fail("cannot write", written < 0 ? errno : EIO);
    data += written;
    left -= static_cast<size_t>(written);
  }
  buffered_ = 0;
}

void OutputFile::commit() {
  flush();
  if (::fsync(fd_) != 0) fail("cannot flush to disk", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail("cannot close", errno);
  if (::rename(temporary_.c_str(), path_.c_str()) != 0)
    fail("cannot rename " + temporary_.string() + " to the output path", errno);
  isCommitted_ = true;
}

}  // namespace iso::io
