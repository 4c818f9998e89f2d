#include "pipeline/base/checkpoint.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <new>
#include <system_error>

#define XXH_INLINE_ALL
#include <xxhash.h>

#include "iso/error.h"
#include "pipeline/base/buffers.h"

namespace iso {
namespace {

constexpr char kMagic[8] = {'I', 'S', 'O', 'C', 'K', 'P', 'T', '1'};

uint64_t hashOf(const std::string& text) { return XXH3_64bits(text.data(), text.size()); }

[[noreturn]] void fileFailure(const std::filesystem::path& path, const std::string& what,
                              int error) {
  throw FileError(path.string(), std::nullopt, what + ": " + std::strerror(error));
}

template <typename T>
std::span<const std::byte> bytesOf(const T& value) {
  return {reinterpret_cast<const std::byte*>(&value), sizeof(T)};
}

// open(2) with O_DIRECT where the file system takes it, else without; `direct` says which.
int openUnbuffered(const std::filesystem::path& path, int flags, bool& direct) {
  int fd = ::open(path.c_str(), flags | O_DIRECT, 0644);
  direct = fd >= 0;
  if (fd < 0 && errno == EINVAL) fd = ::open(path.c_str(), flags, 0644);
  return fd;
}

}  // namespace

// ---- blocks

AlignedBlocks::AlignedBlocks()
    : data_(static_cast<std::byte*>(std::aligned_alloc(kAlignment, kCapacity))) {
  if (!data_) throw std::bad_alloc();
}

void AlignedBlocks::Free::operator()(std::byte* p) const { std::free(p); }

void AlignedBlocks::stopDirect(int fd) {
  if (!direct) return;
  if (const int flags = ::fcntl(fd, F_GETFL); flags >= 0) ::fcntl(fd, F_SETFL, flags & ~O_DIRECT);
  direct = false;
}

// ---- writer

CheckpointWriter::CheckpointWriter(std::filesystem::path final, const std::string& fingerprint)
    : final_(std::move(final)) {
  staged_ = final_;
  staged_ += ".part";
  registration_ = TemporaryRegistration(staged_);
  fd_ = openUnbuffered(staged_, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, buffer_.direct);
  if (fd_ < 0) fileFailure(staged_, "cannot write the checkpoint", errno);
  put({reinterpret_cast<const std::byte*>(kMagic), sizeof kMagic});
  put(bytesOf(hashOf(fingerprint)));
}

CheckpointWriter::~CheckpointWriter() {
  if (fd_ < 0) return;  // committed
  ::close(fd_);
  std::error_code ignored;
  std::filesystem::remove(staged_, ignored);
  refundTemporaryDisk(written_);
}

void CheckpointWriter::put(std::span<const std::byte> data) {
  chargeTemporaryDisk(data.size(), staged_);
  written_ += data.size();
  while (!data.empty()) {
    const size_t n = std::min(data.size(), AlignedBlocks::kCapacity - buffer_.size);
    std::memcpy(buffer_.data() + buffer_.size, data.data(), n);
    buffer_.size += n;
    data = data.subspan(n);
    if (buffer_.size == AlignedBlocks::kCapacity) flush();
  }
}

void CheckpointWriter::flush() {
  if (buffer_.size % AlignedBlocks::kAlignment != 0) buffer_.stopDirect(fd_);  // the tail
  for (size_t done = 0; done < buffer_.size;) {
    const ssize_t w = ::write(fd_, buffer_.data() + done, buffer_.size - done);
    if (w < 0 && errno == EINTR) continue;
    if (w < 0 && errno == EINVAL && buffer_.direct) {  // blocks larger than ours
      buffer_.stopDirect(fd_);
      continue;
    }
    if (w <= 0) fileFailure(staged_, "cannot write the checkpoint", w < 0 ? errno : ENOSPC);
    done += size_t(w);
    if (done % AlignedBlocks::kAlignment != 0) buffer_.stopDirect(fd_);
  }
  buffer_.size = 0;
}

void CheckpointWriter::bytes(const std::string& name, std::span<const std::byte> data) {
  const auto nameLength = uint32_t(name.size());
  put(bytesOf(nameLength));
  put({reinterpret_cast<const std::byte*>(name.data()), name.size()});
  put(bytesOf(uint64_t(data.size())));
  put(data);
  put(bytesOf(uint64_t(XXH3_64bits(data.data(), data.size()))));
}

void CheckpointWriter::json(const std::string& name, const nlohmann::json& value) {
  const std::string text = value.dump();
  bytes(name, {reinterpret_cast<const std::byte*>(text.data()), text.size()});
}

uint64_t CheckpointWriter::commit() {
  put(bytesOf(uint32_t{0}));  // the end
  flush();
  if (::fdatasync(fd_) != 0) fileFailure(staged_, "cannot write the checkpoint", errno);
  ::close(fd_);
  fd_ = -1;
  std::error_code error;
  std::filesystem::rename(staged_, final_, error);
  if (error) fileFailure(final_, "cannot keep the checkpoint", error.value());
  // The rename reaches the disk with the directory.
  if (const int dir = ::open(final_.parent_path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
      dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
  registration_ = {};
  return written_;
}

// ---- reader

CheckpointReader::CheckpointReader(const std::filesystem::path& path,
                                   const std::string& fingerprint)
    : path_(path) {
  fd_ = openUnbuffered(path, O_RDONLY | O_CLOEXEC, buffer_.direct);
  if (fd_ < 0) fail(std::strerror(errno));
  const off_t end = ::lseek(fd_, 0, SEEK_END);
  if (end < 0) fail(std::strerror(errno));
  size_ = uint64_t(end);
  char magic[sizeof kMagic];
  uint64_t hash = 0;
  read({reinterpret_cast<std::byte*>(magic), sizeof magic});
  if (std::memcmp(magic, kMagic, sizeof magic) != 0) fail("not a checkpoint");
  read({reinterpret_cast<std::byte*>(&hash), sizeof hash});
  if (hash != hashOf(fingerprint))
    fail("a checkpoint of another conversion (its inputs, options or version differ)");
}

CheckpointReader::~CheckpointReader() {
  if (fd_ >= 0) ::close(fd_);
}

void CheckpointReader::fail(const std::string& why) const {
  throw CheckpointError(path_.string() + ": " + why);
}

void CheckpointReader::read(std::span<std::byte> data) {
  if (data.size() > size_ - offset_) fail("cut short");
  while (!data.empty()) {
    if (offset_ < bufferStart_ || offset_ >= bufferStart_ + buffer_.size) {
      // The blocks from the one that holds offset_.
      bufferStart_ = offset_ - offset_ % AlignedBlocks::kAlignment;
      buffer_.size = 0;
      ssize_t r = -1;
      while (r < 0) {
        r = ::pread(fd_, buffer_.data(), AlignedBlocks::kCapacity, off_t(bufferStart_));
        if (r < 0 && errno == EINVAL && buffer_.direct)
          buffer_.stopDirect(fd_);
        else if (r < 0 && errno != EINTR)
          fail(std::strerror(errno));
      }
      buffer_.size = size_t(r);
      if (buffer_.size <= offset_ - bufferStart_) fail("cut short");
    }
    const size_t at = size_t(offset_ - bufferStart_);
    const size_t n = std::min(data.size(), buffer_.size - at);
    std::memcpy(data.data(), buffer_.data() + at, n);
    data = data.subspan(n);
    offset_ += n;
  }
}

uint64_t CheckpointReader::begin(const std::string& name) {
  uint32_t nameLength = 0;
  read({reinterpret_cast<std::byte*>(&nameLength), sizeof nameLength});
  if (nameLength != name.size()) fail("expected the section " + name);
  std::string found(nameLength, '\0');
  read({reinterpret_cast<std::byte*>(found.data()), found.size()});
  if (found != name) fail("expected the section " + name + ", found " + found);
  uint64_t size = 0;
  read({reinterpret_cast<std::byte*>(&size), sizeof size});
  // Its data and checksum must be there before anything is made that large.
  if (size > size_ - offset_ || size_ - offset_ - size < sizeof(uint64_t))
    fail("section " + name + " cut short");
  return size;
}

nlohmann::json CheckpointReader::json(const std::string& name) {
  std::string text(begin(name), '\0');
  read({reinterpret_cast<std::byte*>(text.data()), text.size()});
  check(name, {reinterpret_cast<const std::byte*>(text.data()), text.size()});
  nlohmann::json value = nlohmann::json::parse(text, nullptr, false);
  if (value.is_discarded()) fail("section " + name + " is not JSON");
  return value;
}

void CheckpointReader::check(const std::string& name, std::span<const std::byte> data) {
  uint64_t stored = 0;
  read({reinterpret_cast<std::byte*>(&stored), sizeof stored});
  if (stored != XXH3_64bits(data.data(), data.size())) fail("section " + name + " is damaged");
}

void CheckpointReader::finish() {
  uint32_t end = 1;
  read({reinterpret_cast<std::byte*>(&end), sizeof end});
  if (end != 0 || offset_ != size_) fail("more sections than expected");
}

// ---- the directory

ResumeState::ResumeState(std::filesystem::path directory, std::string fingerprint)
    : directory_(std::move(directory)), fingerprint_(std::move(fingerprint)) {
  std::error_code error;
  std::filesystem::create_directory(directory_, error);
  if (error || !std::filesystem::is_directory(directory_))
    throw FileError(directory_.string(), std::nullopt,
                    "cannot keep the state to resume from there: " +
                        (error ? error.message() : std::string("not a directory")));
  // The run the state is of, by its fingerprint's hash: a state of another is removed whole.
  const std::filesystem::path of = directory_ / "fingerprint";
  const std::string hash = std::to_string(hashOf(fingerprint_));
  std::string found;
  if (std::ifstream in(of); in) std::getline(in, found);
  if (found == hash) return;
  bool removed = false;
  for (const auto& entry : std::filesystem::directory_iterator(directory_, error))
    removed |= entry.path() != of && std::filesystem::remove(entry.path(), error);
  if (removed)
    notes_.push_back("the state in " + directory_.string() +
                     " was of another conversion (its inputs, options or version differ): "
                     "removed it, starting over");
  std::ofstream out(of, std::ios::trunc);
  out << hash << "\n";
  if (!out.flush())
    throw FileError(of.string(), std::nullopt, "cannot keep the state to resume from there");
}

bool ResumeState::has(const std::string& name) const {
  std::error_code error;
  return std::filesystem::exists(path(name), error);
}

std::unique_ptr<CheckpointReader> ResumeState::open(const std::string& name) {
  const std::filesystem::path file = path(name);
  if (!has(name)) return nullptr;
  try {
    return std::make_unique<CheckpointReader>(file, fingerprint_);
  } catch (const CheckpointError& e) {
    discard(name, e.what());
    return nullptr;
  }
}

std::unique_ptr<CheckpointWriter> ResumeState::create(const std::string& name) const {
  return std::make_unique<CheckpointWriter>(path(name), fingerprint_);
}

void ResumeState::discard(const std::string& name, const std::string& why) {
  std::error_code ignored;
  std::filesystem::remove(path(name), ignored);
  notes_.push_back("not resumed from " + why + "; removed it");
}

void ResumeState::removeStartingWith(const std::string& prefix) {
  std::error_code error;
  std::vector<std::filesystem::path> names;
  for (const auto& entry : std::filesystem::directory_iterator(directory_, error))
    if (entry.path().filename().string().starts_with(prefix)) names.push_back(entry.path());
  for (const auto& name : names) std::filesystem::remove(name, error);
}

void ResumeState::finish() {
  std::error_code ignored;
  std::filesystem::remove_all(directory_, ignored);
}

}  // namespace iso
