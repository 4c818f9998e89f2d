#include "pipeline/base/buffers.h"

#include <fcntl.h>
#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include "iso/check.h"
#include "pipeline/base/process.h"
#include "pipeline/base/progress.h"
#include "base/text.h"

namespace iso {
namespace {
constexpr size_t kHugePage = size_t{2} << 20;
}

void* allocateLarge(size_t bytes) {
  if (bytes < kHugePage) {
    if (void* p = std::malloc(std::max<size_t>(bytes, 1))) return p;
    throw std::bad_alloc();
  }
  void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  madvise(p, bytes, MADV_HUGEPAGE);  // a hint: without it, 4 KiB pages
  return p;
}

void deallocateLarge(void* p, size_t bytes) noexcept {
  if (!p) return;
  if (bytes < kHugePage) {
    std::free(p);
  } else {
    munmap(p, bytes);
  }
}

// ---- Temporary disk

namespace {
std::atomic<uint64_t> temporaryBytes{0}, temporaryPeak{0}, temporaryLimit{0};
}  // namespace

void chargeTemporaryDisk(uint64_t bytes, const std::filesystem::path& where) {
  const uint64_t limit = temporaryLimit.load();
  uint64_t now = temporaryBytes.load();
  do {
    if (limit > 0 && now + bytes > limit)
      throw std::runtime_error(where.string() + ": the temporary files would exceed --max-temp " +
                               byteSize(limit) + " (" + byteSize(now) + " in use, " +
                               byteSize(bytes) + " more needed)");
  } while (!temporaryBytes.compare_exchange_weak(now, now + bytes));
  uint64_t peak = temporaryPeak.load();
  while (now + bytes > peak && !temporaryPeak.compare_exchange_weak(peak, now + bytes)) {
  }
}

void refundTemporaryDisk(uint64_t bytes) noexcept { temporaryBytes -= bytes; }

TemporaryDiskStats temporaryDiskStats() {
  return {temporaryBytes.load(), temporaryPeak.load(), temporaryLimit.load()};
}

TemporaryDiskLimit::TemporaryDiskLimit(uint64_t bytes) {
  temporaryLimit = bytes;
  temporaryPeak = temporaryBytes.load();
}

TemporaryDiskLimit::~TemporaryDiskLimit() { temporaryLimit = 0; }

// ---- Spilled arrays

namespace {

// The one active area's settings and every spilled mapping (they may outlive the area: a mapping
// is known by its address until it is freed).
struct SpillState {
  std::mutex mutex;
  bool active = false;
  std::filesystem::path directory;
  uint64_t residentLimit = 0, minBytes = 0;
  std::map<void*, size_t> mappings;
  SpillArea::Stats stats;
  // The pager.
  std::thread pager;
  std::condition_variable wake;
  bool stopping = false;
  // Set while the pager drops pages with the process past the limit (spillPause waits on it).
  std::atomic<bool> pause{false};
  std::atomic<uint64_t> pauses{0};
  std::mutex pauseMutex;
  std::condition_variable resumed;
};

SpillState& state() {
  static SpillState s;
  return s;
}

size_t pageSize() {
  static const size_t size = size_t(sysconf(_SC_PAGESIZE));
  return size;
}

size_t roundToPages(size_t bytes) {
  const size_t page = pageSize();
  return (std::max<size_t>(bytes, 1) + page - 1) / page * page;
}

void releaseLocked(SpillState& s) {
  for (const auto& [p, bytes] : s.mappings) madvise(p, roundToPages(bytes), MADV_DONTNEED);
  ++s.stats.releases;
}

constexpr uint64_t kMinFilePages = uint64_t{64} << 20;
constexpr size_t kDropSlice = size_t{32} << 20;

// Sets or clears SpillState::pause, waking the threads that wait in spillPause when cleared.
void setPause(SpillState& s, bool on) {
  if (s.pause.load() == on) return;
  {
    std::lock_guard lock(s.pauseMutex);
    s.pause = on;
  }
  if (!on) s.resumed.notify_all();
}

// Drop spilled pages a slice of 32 MiB at a time, going on from where the last drop stopped, until
// the process is at or below `target`; returns the most it was seen at meanwhile. While a drop
// runs, the stages go on mapping pages, and a read fault maps its cached neighbours too (fault-
// around: 12 pages a random read here), so a whole drop of a large resident set let the process
// grow past the limit before the drop took effect; slices are looked between, and stop early.
uint64_t dropUntil(SpillState& s, uint64_t target, void*& resume, size_t& resumeOffset) {
  uint64_t most = 0;
  // The last arrays may have been freed since the pager looked (it reads the process's memory
  // without the lock); with no mapping, begin() is end(), and stepping past it never ends.
  if (s.mappings.empty()) return most;
  auto it = s.mappings.lower_bound(resume);
  size_t offset = it != s.mappings.end() && it->first == resume ? resumeOffset : 0;
  for (size_t visited = 0; visited <= s.mappings.size(); ++visited, offset = 0) {
    if (it == s.mappings.end()) it = s.mappings.begin();
    const size_t length = roundToPages(it->second);
    for (; offset < length; offset += kDropSlice) {
      madvise(static_cast<char*>(it->first) + offset, std::min(kDropSlice, length - offset),
              MADV_DONTNEED);
      const uint64_t all = currentRssBytes();
      most = std::max(most, all);
      if (all > s.residentLimit) setPause(s, true);
      if (all <= target) {
        resume = it->first;
        resumeOffset = offset + kDropSlice;
        ++s.stats.releases;
        return most;
      }
    }
    ++it;
  }
  resume = nullptr;
  ++s.stats.releases;
  return most;
}

void pagerLoop() {
  SpillState& s = state();
  std::unique_lock lock(s.mutex);
  // The most the process grew between two looks, and the most it went past the limit while a
  // drop ran, both decaying by half in about 3 s.
  double burst = 0.0, overshoot = 0.0;
  uint64_t last = 0;
  void* resume = nullptr;  // where the next drop starts
  size_t resumeOffset = 0;
  const uint64_t limit = s.residentLimit;
  while (!s.stopping) {
    s.wake.wait_for(lock, std::chrono::milliseconds(2));
    if (s.stopping || s.mappings.empty()) continue;
    lock.unlock();
    uint64_t files = 0;
    const uint64_t all = currentRssBytes(&files);
    lock.lock();
    // Mapping cached pages again is fast, and the stages map them at up to 5 GB/s (fault-
    // around), so the pager acts early: by twice the largest growth seen between two looks
    // lately plus twice the most the process went past the limit during a drop lately (at least
    // a sixteenth of the limit, at most seven eighths), when more than a sixteenth of the limit
    // (64 MiB at least: below that, a drop saves less than the faults cost) is file pages. It
    // drops to three margins below the limit.
    burst = std::max(burst * 0.9995, all > last ? double(all - last) : 0.0);
    overshoot *= 0.9995;
    last = all;
    const uint64_t margin =
        std::clamp<uint64_t>(uint64_t(2.0 * (burst + overshoot)), limit / 16, limit / 8 * 7);
    if (all > limit - margin && files > std::max(limit / 16, kMinFilePages)) {
      const uint64_t target = limit > 3 * margin ? limit - 3 * margin : 0;
      if (all > limit) setPause(s, true);
      const uint64_t most = dropUntil(s, target, resume, resumeOffset);
      setPause(s, false);  // the threads paused while it ran go on
      if (most > limit) overshoot = std::max(overshoot, double(most - limit));
      last = currentRssBytes();
    }
  }
}

}  // namespace

void spillPause() {
  SpillState& s = state();
  if (!s.pause.load(std::memory_order_relaxed)) return;
  s.pauses.fetch_add(1, std::memory_order_relaxed);
  std::unique_lock lock(s.pauseMutex);
  // (A bound on the wait: a drop of every array ends well within it.)
  s.resumed.wait_for(lock, std::chrono::milliseconds(200), [&] { return !s.pause.load(); });
}

namespace {

// A file of `bytes` in the directory, mapped shared.
void* mapSpillFile(const std::filesystem::path& directory, size_t bytes) {
  const size_t length = roundToPages(bytes);
  chargeTemporaryDisk(length, directory);  // first: past --max-temp, nothing is made
  const std::string where = directory.string();
  int fd = open(where.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd < 0 && (errno == EOPNOTSUPP || errno == EISDIR || errno == EINVAL)) {
    // No unnamed files on this file system: a named one, removed at once.
    std::string name = (directory / ".iso-array.XXXXXX").string();
    fd = mkostemp(name.data(), O_CLOEXEC);
    if (fd >= 0) unlink(name.c_str());
  }
  const auto fail = [&](const char* what, int error) {
    if (fd >= 0) close(fd);
    refundTemporaryDisk(length);
    throw std::runtime_error(where + ": cannot " + what + " " + std::to_string(bytes) +
                             " bytes of temporary point data: " + std::strerror(error));
  };
  if (fd < 0) fail("create a file for", errno);
  if (const int error = posix_fallocate(fd, 0, off_t(length)); error != 0)
    fail("reserve", error);  // a full disk: an error now rather than SIGBUS when a page is written
  void* p = mmap(nullptr, length, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) fail("map", errno);
  // No readahead, and so page-cache folios of one page: a fault then maps 4 KiB, not a large
  // folio (ext4 maps 512 MiB of cached large folios in 5 ms), and the pager keeps up.
  madvise(p, length, MADV_RANDOM);
  close(fd);  // the mapping keeps the file; unmapping removes it
  return p;
}

}  // namespace

void keepLargeBlocksOutOfTheHeap() {
  // glibc raises its mmap threshold (up to 32 MiB) each time a large block is freed, and blocks
  // below it come from the heap, where freed memory stays resident for the next allocation: the
  // stages' work lists then held 145-220 MiB of anonymous memory between them on the 20M dragon
  // under --memory 512M (75-112 MiB with a fixed threshold from the start), room the pager could
  // not give the spilled arrays. A fixed threshold keeps every block of 256 KiB or more a mapping
  // of its own, returned when freed.
  mallopt(M_MMAP_THRESHOLD, 256 << 10);
}

SpillArea::SpillArea(const std::filesystem::path& directory, uint64_t residentLimit,
                     uint64_t minBytes) {
  SpillState& s = state();
  std::lock_guard lock(s.mutex);
  ISO_CHECK(!s.active);  // one spill area at a time
  s.active = true;
  s.directory = directory;
  s.residentLimit = residentLimit;
  s.minBytes = std::max<uint64_t>(minBytes, 1);
  s.stats = Stats{};
  s.pauses = 0;
  for (const auto& [p, bytes] : s.mappings) s.stats.bytes += bytes;
  s.stats.peakBytes = s.stats.bytes;
  s.stopping = false;
  s.pager = std::thread(pagerLoop);
  if (residentLimit > 0) keepLargeBlocksOutOfTheHeap();
}

SpillArea::~SpillArea() {
  SpillState& s = state();
  {
    std::lock_guard lock(s.mutex);
    s.stopping = true;
    s.active = false;
  }
  s.wake.notify_all();
  s.pager.join();
}

SpillArea::Stats SpillArea::stats() {
  SpillState& s = state();
  std::lock_guard lock(s.mutex);
  Stats stats = s.stats;
  stats.pauses = s.pauses.load();
  return stats;
}

uint64_t SpillArea::residentLimit() {
  SpillState& s = state();
  std::lock_guard lock(s.mutex);
  return s.active ? s.residentLimit : 0;
}

void SpillArea::release() {
  SpillState& s = state();
  std::lock_guard lock(s.mutex);
  releaseLocked(s);
}

// The file is made and mapped, and unmapped, outside the lock, so that the pager is never held up
// by a large one.
void* allocateSpillable(size_t bytes) {
  SpillState& s = state();
  std::filesystem::path directory;
  {
    std::lock_guard lock(s.mutex);
    if (!s.active || bytes < s.minBytes) return allocateLarge(bytes);
    directory = s.directory;
  }
  void* p = mapSpillFile(directory, bytes);
  std::lock_guard lock(s.mutex);
  s.mappings.emplace(p, bytes);
  s.stats.bytes += bytes;
  s.stats.peakBytes = std::max(s.stats.peakBytes, s.stats.bytes);
  ++s.stats.arrays;
  return p;
}

void deallocateSpillable(void* p, size_t bytes) noexcept {
  if (!p) return;
  SpillState& s = state();
  bool spilled = false;
  {
    std::lock_guard lock(s.mutex);
    if (const auto it = s.mappings.find(p); it != s.mappings.end()) {
      spilled = true;
      s.stats.bytes -= it->second;
      s.mappings.erase(it);
    }
  }
  if (spilled) {
    munmap(p, roundToPages(bytes));
    refundTemporaryDisk(roundToPages(bytes));
  } else {
    deallocateLarge(p, bytes);
  }
}

}  // namespace iso
