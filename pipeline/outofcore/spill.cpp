#include "pipeline/outofcore/spill.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <glm/common.hpp>
#include <limits>
#include <numeric>

#include "iso/error.h"
#include "pipeline/base/buffers.h"
#include "pipeline/base/progress.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr size_t kWriteBuffer = size_t{1} << 20;
constexpr uint64_t kBatchPoints = uint64_t{1} << 18;

size_t rawRecordBytes(const PointLayout& l) {
  return 3 * sizeof(double) + (l.normals ? 12 : 0) + (l.colors ? 12 : 0) +
         (l.scalar.empty() ? 0 : 8);
}

// Encode point i of a cloud into a raw record.
void encodeRaw(const PointCloud& cloud, size_t i, const PointLayout& l, std::byte* out) {
  std::memcpy(out, &cloud.positions[i], 24);
  out += 24;
  if (l.normals) {
    std::memcpy(out, &cloud.normals[i], 12);
    out += 12;
  }
  if (l.colors) {
    std::memcpy(out, &cloud.colors[i], 12);
    out += 12;
  }
  if (!l.scalar.empty()) std::memcpy(out, &cloud.extras[i], 8);
}

void decodeRaw(const std::byte* in, const PointLayout& l, PointCloud& cloud) {
  glm::dvec3 p;
  std::memcpy(&p, in, 24);
  cloud.positions.push_back(p);
  in += 24;
  if (l.normals) {
    glm::vec3 n;
    std::memcpy(&n, in, 12);
    cloud.normals.push_back(n);
    in += 12;
  }
  if (l.colors) {
    glm::vec3 c;
    std::memcpy(&c, in, 12);
    cloud.colors.push_back(c);
    in += 12;
  }
  if (!l.scalar.empty()) {
    double v;
    std::memcpy(&v, in, 8);
    if (cloud.extraNames.empty()) cloud.extraNames = {l.scalar};
    cloud.extras.push_back(v);
  }
}

uint64_t fineCellOf(const glm::dvec3& world, const Frame& frame) {
  return keyOfWorld(world, frame) >> (3 * (kMaxLevel - Distribution::kFineLevel));
}

}  // namespace

// ---- SpillDirectory

SpillDirectory::SpillDirectory(const std::filesystem::path& parent, const std::string& tag) {
  static std::atomic<uint64_t> sequence{0};
  const std::filesystem::path base = parent.empty() ? "." : parent;
  path_ = base / (".iso-spill" + (tag.empty() ? "" : "-" + tag) + "." + std::to_string(::getpid()) +
                  "-" + std::to_string(sequence++) + ".isotmp");
  registrations_.emplace_back(path_);  // unlinked (if empty) last, after the files
  std::error_code error;
  if (!std::filesystem::create_directory(path_, error) || error)
    throw FileError(base.string(), std::nullopt,
                    "cannot make a directory for temporary files there: " +
                        (error ? error.message() : std::string("it exists")));
}

SpillDirectory::~SpillDirectory() {
  std::error_code ignored;
  std::filesystem::remove_all(path_, ignored);
}

std::filesystem::path SpillDirectory::newFile(const std::string& name) {
  std::filesystem::path file = path_ / name;
  registrations_.emplace_back(file);
  return file;
}

uint64_t SpillDirectory::bytes() const {
  uint64_t total = 0;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator(path_, error))
    if (entry.is_regular_file(error)) total += entry.file_size(error);
  return total;
}

// ---- RecordFile

RecordFile::RecordFile(std::filesystem::path path, size_t recordBytes)
    : path_(std::move(path)), recordBytes_(recordBytes) {
  fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd_ < 0) fail("cannot create", errno);
  buffer_.reserve(kWriteBuffer);
}

RecordFile::~RecordFile() {
  if (fd_ >= 0) ::close(fd_);
  ::unlink(path_.c_str());
  refundTemporaryDisk(charged_);
}

void RecordFile::fail(const std::string& what, int error) const {
  throw FileError(path_.string(), std::nullopt,
                  what + " (temporary file): " + std::strerror(error));
}

void RecordFile::append(std::span<const std::byte> records) {
  if (buffer_.size() + records.size() > kWriteBuffer) flush();
  if (records.size() > kWriteBuffer) {
    writeAt(count_, records);
    return;
  }
  buffer_.insert(buffer_.end(), records.begin(), records.end());
  count_ += records.size() / recordBytes_;
}

void RecordFile::flush() {
  if (buffer_.empty()) return;
  const uint64_t first = count_ - buffer_.size() / recordBytes_;
  std::vector<std::byte> pending;
  pending.swap(buffer_);
  buffer_.reserve(kWriteBuffer);
  const uint64_t saved = count_;
  writeAt(first, pending);
  count_ = saved;
}

void RecordFile::writeAt(uint64_t index, std::span<const std::byte> records) {
  uint64_t offset = index * recordBytes_;
  if (const uint64_t end = offset + records.size(); end > charged_) {
    chargeTemporaryDisk(end - charged_, path_);  // throws past --max-temp, before writing
    charged_ = end;
  }
  while (!records.empty()) {
    const ssize_t n = ::pwrite(fd_, records.data(), records.size(), off_t(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot write", n < 0 ? errno : ENOSPC);
    records = records.subspan(size_t(n));
    offset += uint64_t(n);
  }
  count_ = std::max(count_, offset / recordBytes_);
}

void RecordFile::read(uint64_t first, uint64_t count, std::vector<std::byte>& out) const {
  out.resize(count * recordBytes_);
  size_t done = 0;
  while (done < out.size()) {
    const ssize_t n =
        ::pread(fd_, out.data() + done, out.size() - done, off_t(first * recordBytes_ + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot read back", n < 0 ? errno : EIO);
    done += size_t(n);
  }
}

// ---- RawSpill

RawSpill::RawSpill(SpillDirectory& directory, PointLayout layout)
    : layout_(layout),
      file_(std::make_unique<RecordFile>(directory.newFile("raw"), rawRecordBytes(layout))),
      lo_(std::numeric_limits<double>::max()),
      hi_(-std::numeric_limits<double>::max()) {}

void RawSpill::append(const PointCloud& batch) {
  std::vector<std::byte> records(batch.size() * file_->recordBytes());
  for (size_t i = 0; i < batch.size(); ++i) {
    encodeRaw(batch, i, layout_, records.data() + i * file_->recordBytes());
    lo_ = glm::min(lo_, batch.positions[i]);
    hi_ = glm::max(hi_, batch.positions[i]);
  }
  file_->append(records);
}

void RawSpill::finish() { file_->flush(); }

void RawSpill::forEachBatch(const std::function<void(const PointCloud&, uint64_t first)>& f) const {
  std::vector<std::byte> records;
  PointCloud batch;
  for (uint64_t first = 0; first < size(); first += kBatchPoints) {
    const uint64_t count = std::min(kBatchPoints, size() - first);
    file_->read(first, count, records);
    batch.clear();
    for (uint64_t i = 0; i < count; ++i)
      decodeRaw(records.data() + i * file_->recordBytes(), layout_, batch);
    f(batch, first);
  }
}

// ---- Distribution

Distribution::Distribution(SpillDirectory& directory, const RawSpill& raw, const Frame& frame,
                           uint64_t maxChunkPoints, const std::vector<uint8_t>* keep)
    : layout_(raw.layout()), frame_(frame) {
  const size_t rawBytes = rawRecordBytes(layout_);
  const size_t recordBytes = rawBytes + sizeof(uint32_t);  // + input index
  file_ = std::make_unique<RecordFile>(directory.newFile("chunks"), recordBytes);
  const auto kept = [&](uint64_t i) { return keep == nullptr || (*keep)[i] != 0; };

  // Count points per fine cell; their prefix sums place every cell, so every chunk, on disk.
  constexpr uint64_t kCells = uint64_t{1} << (3 * kFineLevel);
  std::vector<uint64_t> start(kCells + 1, 0);
  raw.forEachBatch([&](const PointCloud& batch, uint64_t first) {
    for (size_t i = 0; i < batch.size(); ++i)
      if (kept(first + i)) ++start[fineCellOf(batch.positions[i], frame) + 1];
    progressAdvance(batch.size());
  });
  std::partial_sum(start.begin(), start.end(), start.begin());
  for (uint64_t c = 0; c < kCells; ++c)
    if (start[c + 1] > start[c]) cells_.push_back({c, start[c], start[c + 1]});

  // Chunks: cells split until they hold at most maxChunkPoints (or are fine cells).
  const auto plan = [&](auto&& self, int level, uint64_t key) -> void {
    const int shift = 3 * (kFineLevel - level);
    const uint64_t count = start[(key + 1) << shift] - start[key << shift];
    if (count == 0) return;
    if (count <= maxChunkPoints || level == kFineLevel) {
      chunks_.push_back({uint8_t(level), key, start[key << shift], start[(key + 1) << shift]});
      return;
    }
    for (uint64_t child = 0; child < 8; ++child) self(self, level + 1, key * 8 + child);
  };
  plan(plan, 0, 0);

  // Scatter in input order into each chunk's range, through one buffer per chunk (64 MiB in
  // all, so that writes stay large whatever the input order); then place each chunk's records by
  // fine cell, in memory, at the cells' offsets (input order within a cell).
  std::vector<uint32_t> chunkOf(kCells, 0);
  for (uint32_t c = 0; c < chunks_.size(); ++c) {
    const int shift = 3 * (kFineLevel - chunks_[c].level);
    std::fill(chunkOf.begin() + ptrdiff_t(chunks_[c].key << shift),
              chunkOf.begin() + ptrdiff_t((chunks_[c].key + 1) << shift), c);
  }
  const size_t perChunk =
      std::clamp<size_t>((size_t{64} << 20) / recordBytes / chunks_.size(), 64, size_t{1} << 16);
  std::vector<std::vector<std::byte>> buffers(chunks_.size());
  std::vector<uint64_t> fill(chunks_.size());
  for (size_t c = 0; c < chunks_.size(); ++c) fill[c] = chunks_[c].begin;
  const auto flush = [&](size_t c) {
    file_->writeAt(fill[c], buffers[c]);
    fill[c] += buffers[c].size() / recordBytes;
    buffers[c].clear();
  };
  raw.forEachBatch([&](const PointCloud& batch, uint64_t first) {
    std::vector<std::byte> record(recordBytes);
    for (size_t i = 0; i < batch.size(); ++i) {
      if (!kept(first + i)) continue;
      const uint32_t c = chunkOf[fineCellOf(batch.positions[i], frame)];
      encodeRaw(batch, i, layout_, record.data());
      const auto index = uint32_t(first + i);
      std::memcpy(record.data() + rawBytes, &index, sizeof index);
      buffers[c].insert(buffers[c].end(), record.begin(), record.end());
      if (buffers[c].size() >= perChunk * recordBytes) flush(c);
    }
    progressAdvance(batch.size());
  });
  for (size_t c = 0; c < chunks_.size(); ++c)
    if (!buffers[c].empty()) flush(c);
  buffers = {};
  chunkOf = {};

  std::vector<std::byte> records, placed;
  for (const SpillChunk& chunk : chunks_) {
    file_->read(chunk.begin, chunk.size(), records);
    placed.resize(records.size());
    for (uint64_t i = 0; i < chunk.size(); ++i) {
      const std::byte* r = records.data() + i * recordBytes;
      glm::dvec3 p;
      std::memcpy(&p, r, 24);
      const uint64_t slot = start[fineCellOf(p, frame)]++ - chunk.begin;
      std::memcpy(placed.data() + slot * recordBytes, r, recordBytes);
    }
    file_->writeAt(chunk.begin, placed);
  }
}

void Distribution::decode(const std::vector<std::byte>& records, LoadedPoints& out,
                          const std::function<bool(const glm::dvec3&)>& accept) const {
  const size_t recordBytes = file_->recordBytes();
  const size_t count = records.size() / recordBytes;
  for (size_t i = 0; i < count; ++i) {
    const std::byte* r = records.data() + i * recordBytes;
    glm::dvec3 p;
    std::memcpy(&p, r, 24);
    if (accept && !accept(p)) continue;
    decodeRaw(r, layout_, out.cloud);
    uint32_t index = 0;
    std::memcpy(&index, r + recordBytes - sizeof index, sizeof index);
    out.source.push_back(index);
  }
}

LoadedPoints Distribution::load(const SpillChunk& chunk) const {
  std::vector<std::byte> records;
  file_->read(chunk.begin, chunk.size(), records);
  LoadedPoints out;
  decode(records, out, {});
  return out;
}

LoadedPoints Distribution::loadBox(const glm::dvec3& lo, const glm::dvec3& hi,
                                   const SpillChunk& except) const {
  LoadedPoints out;
  const double cell = std::ldexp(1.0, -kFineLevel);
  const int exceptShift = 3 * (kFineLevel - except.level);
  const auto accept = [&](const glm::dvec3& world) {
    const glm::vec3 u(toFrame(world, frame_));
    return u.x >= lo.x && u.y >= lo.y && u.z >= lo.z && u.x <= hi.x && u.y <= hi.y && u.z <= hi.z;
  };
  std::vector<std::byte> records;
  uint64_t runBegin = 0, runEnd = 0;
  const auto readRun = [&] {
    if (runEnd == runBegin) return;
    file_->read(runBegin, runEnd - runBegin, records);
    decode(records, out, accept);
    runBegin = runEnd = 0;
  };
  for (const FineCell& c : cells_) {
    if ((c.key >> exceptShift) == except.key) continue;
    const std::array<uint32_t, 3> xyz = mortonDecode(c.key);
    bool overlaps = true;
    for (int a = 0; a < 3; ++a) {
      const double cellLo = xyz[size_t(a)] * cell;
      // A margin of one float step: positions are compared after rounding to float.
      overlaps = overlaps && cellLo <= hi[a] + 1e-6 && cellLo + cell >= lo[a] - 1e-6;
    }
    if (!overlaps) continue;
    if (c.begin != runEnd) readRun();
    if (runEnd == runBegin) runBegin = c.begin;
    runEnd = c.end;
  }
  readRun();
  return out;
}

}  // namespace iso
