// Spilled arrays (pipeline/buffers.h): file-backed while an area exists, the same values after
// their pages are dropped, nothing left in the directory, and a clear error when the file
// cannot be made.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <malloc.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numeric>

#include "pipeline/base/buffers.h"
#include "pipeline/base/process.h"
#include "pipeline/outofcore/spill.h"
#include "tests/support/support.h"

namespace iso {
namespace {

// Resident pages mapped from files, in bytes.
uint64_t residentFileBytes() {
  uint64_t files = 0;
  currentRssBytes(&files);
  return files;
}

bool directoryIsEmpty(const std::filesystem::path& dir) {
  return std::filesystem::directory_iterator(dir) == std::filesystem::directory_iterator();
}

TEST(SpillArea, largeArraysLiveInFilesAndKeepTheirValuesWhenTheirPagesAreDropped) {
  test::TempDir dir;
  constexpr size_t n = size_t{16} << 20;  // 128 MiB of uint64_t
  {
    // A limit no process meets, so that only release() drops pages here.
    SpillArea area(dir.path(), uint64_t{1} << 50, uint64_t{1} << 20);
    SpillVector<uint64_t> small(1000);  // below minBytes: in memory
    EXPECT_EQ(SpillArea::stats().arrays, 0u);
    EXPECT_EQ(small[999], 0u);  // value-initialized like std::vector's
    const uint64_t before = residentFileBytes();
    SpillVector<uint64_t> large(n);
    EXPECT_EQ(SpillArea::stats().arrays, 1u);
    EXPECT_GE(SpillArea::stats().bytes, n * sizeof(uint64_t));
    for (size_t i = 0; i < n; ++i) large[i] = i * 2654435761u;
    const uint64_t filled = residentFileBytes();
    EXPECT_GE(filled, before + n * sizeof(uint64_t) * 9 / 10) << "the array is not file-backed";
    SpillArea::release();
    EXPECT_LT(residentFileBytes(), before + n * sizeof(uint64_t) / 10)
        << "its pages are still resident";
    EXPECT_GE(SpillArea::stats().releases, 1u);
    uint64_t wrong = 0;
    for (size_t i = 0; i < n; ++i) wrong += large[i] != i * 2654435761u;
    EXPECT_EQ(wrong, 0u);
    // Growing copies into a new file; the old one goes.
    large.push_back(7);
    EXPECT_EQ(large.back(), 7u);
    EXPECT_EQ(large[n - 1], (n - 1) * 2654435761u);
    EXPECT_EQ(SpillArea::stats().arrays, 2u);
    EXPECT_TRUE(directoryIsEmpty(dir.path())) << "the files have no names";
  }
  EXPECT_TRUE(directoryIsEmpty(dir.path()));
}

TEST(SpillArea, thePagerKeepsTheProcessNearItsLimit) {
  test::TempDir dir;
  const uint64_t before = residentFileBytes();
  SpillArea area(dir.path(), 1, 4096);  // over the limit always: every look may drop pages
  // 128 MiB: more than the 64 MiB of file pages below which the pager leaves them.
  SpillVector<uint32_t> values(size_t{32} << 20);
  std::iota(values.begin(), values.end(), 0u);
  for (int i = 0; i < 200 && SpillArea::stats().releases == 0; ++i) usleep(10000);
  EXPECT_GT(SpillArea::stats().releases, 0u);
  EXPECT_LT(residentFileBytes(), before + (uint64_t{64} << 20)) << "the array is still resident";
  for (size_t i = 0; i < values.size(); i += 4099) ASSERT_EQ(values[i], uint32_t(i));
}

// Under a limit, freed blocks of 256 KiB or more go back to the system: a block of 1 MiB after a
// freed one of 16 MiB is a mapping of its own (glibc alone would have raised its threshold to 16
// MiB and served it from the heap, where it stays resident once freed).
TEST(SpillArea, aLimitKeepsLargeBlocksOutOfTheHeap) {
  test::TempDir dir;
  SpillArea area(dir.path(), uint64_t{1} << 50, uint64_t{1} << 20);
  void* large = std::malloc(size_t{16} << 20);
  ASSERT_NE(large, nullptr);
  static_cast<volatile char*>(large)[0] = 1;
  std::free(large);
  const size_t mapped = mallinfo2().hblkhd;
  void* block = std::malloc(size_t{1} << 20);
  ASSERT_NE(block, nullptr);
  EXPECT_GE(mallinfo2().hblkhd, mapped + (size_t{1} << 20)) << "the block came from the heap";
  std::free(block);
  EXPECT_EQ(mallinfo2().hblkhd, mapped);
}

// Past the limit, the pager makes the threads that call spillPause wait while it drops pages;
// under it, and with no area, spillPause returns at once. (With a limit of 1 byte every look drops,
// and a thread that touches pages and pauses between them must meet some of those drops.)
TEST(SpillArea, threadsPauseWhileThePagerDropsPastTheLimit) {
  test::TempDir dir;
  spillPause();                           // no area: nothing to wait for
  constexpr size_t n = size_t{32} << 20;  // 128 MiB: more file pages than the pager leaves
  {
    SpillArea area(dir.path(), uint64_t{1} << 50, 4096);
    SpillVector<uint32_t> values(n);
    for (size_t i = 0; i < n; ++i) {
      values[i] = uint32_t(i);
      if (i % 4096 == 0) spillPause();
    }
    EXPECT_EQ(SpillArea::stats().pauses, 0u) << "paused under the limit";
  }
  SpillArea area(dir.path(), 1, 4096);
  SpillVector<uint32_t> values(n);
  const auto start = std::chrono::steady_clock::now();
  uint64_t wrong = 0;
  for (int round = 0; SpillArea::stats().pauses == 0 &&
                      std::chrono::steady_clock::now() - start < std::chrono::seconds(20);
       ++round)
    for (size_t i = 0; i < n; ++i) {
      if (round == 0) values[i] = uint32_t(i);
      wrong += values[i] != uint32_t(i);
      if (i % 1024 == 0) spillPause();  // every 4 KiB page
    }
  EXPECT_GT(SpillArea::stats().pauses, 0u) << "no thread ever waited for a drop";
  EXPECT_GT(SpillArea::stats().releases, 0u);
  EXPECT_EQ(wrong, 0u);
}

// The pager reads the process's memory without its lock; an array freed meanwhile may have been
// the last one, and the drop that follows finds none. File pages of a file of its own keep every
// look dropping while a small spilled array comes and goes; the area still ends (a drop over no
// mapping once stepped past the map's end for ever, and the area's end waited for it).
TEST(SpillArea, thePagerSurvivesTheLastArrayFreedWhileItLooks) {
  test::TempDir dir;
  const std::filesystem::path held = dir / "held";
  constexpr size_t kHeld = size_t{96} << 20;  // over the 64 MiB of file pages the pager leaves
  test::writeFile(held, std::vector<std::byte>(1));
  std::filesystem::resize_file(held, kHeld);
  const int fd = open(held.c_str(), O_RDWR);
  ASSERT_GE(fd, 0);
  auto* pages =
      static_cast<uint8_t*>(mmap(nullptr, kHeld, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0));
  close(fd);
  ASSERT_NE(pages, MAP_FAILED);
  {
    SpillArea area(dir.path(), 1, 4096);
    const auto start = std::chrono::steady_clock::now();
    uint64_t rounds = 0;
    // Two seconds, and on until the pager has dropped pages (it looks less often on a loaded
    // machine), for 20 at most.
    const auto elapsed = [&] { return std::chrono::steady_clock::now() - start; };
    while (elapsed() < std::chrono::seconds(2) ||
           (SpillArea::stats().releases == 0 && elapsed() < std::chrono::seconds(20))) {
      for (size_t i = 0; i < kHeld; i += 4096) pages[i] = uint8_t(i);  // resident again
      for (int j = 0; j < 200; ++j, ++rounds) {
        SpillVector<uint32_t> small(2048);  // 8 KiB: a spilled file of its own
        small[7] = 7;
        ASSERT_EQ(small[7], 7u);
      }
    }
    EXPECT_GT(SpillArea::stats().releases, 0u) << "the pager never dropped pages";
    EXPECT_GT(rounds, 1000u);
  }
  munmap(pages, kHeld);
}

TEST(SpillArea, aDirectoryThatCannotHoldTheFileIsAClearError) {
  test::TempDir dir;
  const std::filesystem::path missing = dir / "missing";
  SpillArea area(missing, uint64_t{1} << 50, 4096);
  try {
    SpillVector<uint64_t> v(100000);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(missing.string()), std::string::npos) << what;
    EXPECT_NE(what.find("800000 bytes"), std::string::npos) << what;
  }
}

TEST(TemporaryDisk, everyTemporaryFileIsChargedAndALimitStopsBeforeWriting) {
  test::TempDir dir;
  const uint64_t before = temporaryDiskStats().bytes;
  {
    TemporaryDiskLimit limit(uint64_t{1} << 20);  // 1 MiB
    SpillArea area(dir.path(), uint64_t{1} << 50, 4096);
    SpillVector<uint64_t> a(65536);  // 512 KiB: charged
    EXPECT_EQ(temporaryDiskStats().bytes, before + (512u << 10));
    RecordFile records(dir / "records", 16);
    const std::vector<std::byte> block(256u << 10);
    records.append(block);
    records.flush();
    EXPECT_EQ(temporaryDiskStats().bytes, before + (768u << 10));
    records.writeAt(0, block);  // within the file: nothing more
    EXPECT_EQ(temporaryDiskStats().bytes, before + (768u << 10));
    try {
      SpillVector<uint64_t> b(65536);  // 512 KiB more: past the limit
      FAIL() << "no error";
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(dir.path().string()), std::string::npos) << what;
      EXPECT_NE(what.find("--max-temp 1.0 MiB"), std::string::npos) << what;
    }
    EXPECT_THROW(records.writeAt(32768, block), std::runtime_error);
    EXPECT_EQ(std::filesystem::file_size(dir / "records"), 256u << 10) << "written past the limit";
    EXPECT_EQ(temporaryDiskStats().bytes, before + (768u << 10)) << "a refused charge stays";
    EXPECT_EQ(temporaryDiskStats().peakBytes, before + (768u << 10));
    EXPECT_EQ(temporaryDiskStats().limit, uint64_t{1} << 20);
  }
  // Freed arrays and removed files are refunded.
  EXPECT_EQ(temporaryDiskStats().bytes, before);
  EXPECT_EQ(temporaryDiskStats().limit, 0u);
}

}  // namespace
}  // namespace iso
