// Buffers for large arrays that parallel code fills right away: elements are left
// default-initialized (numbers: not zeroed first), and buffers of 2 MiB or more are mapped with
// transparent huge pages where the system allows (a page fault for every 4 KiB of a large
// input's arrays costs more than some stages' own work).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace iso {

void* allocateLarge(size_t bytes);
void deallocateLarge(void* p, size_t bytes) noexcept;

template <typename T>
struct DefaultInitAllocator {
  using value_type = T;
  DefaultInitAllocator() = default;
  template <typename U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) {}
  T* allocate(size_t n) { return static_cast<T*>(allocateLarge(n * sizeof(T))); }
  void deallocate(T* p, size_t n) noexcept { deallocateLarge(p, n * sizeof(T)); }
  template <typename U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <typename U>
  bool operator==(const DefaultInitAllocator<U>&) const {
    return true;
  }
};

template <typename T>
using UninitializedVector = std::vector<T, DefaultInitAllocator<T>>;

// Blocks of 256 KiB or more get mappings of their own from now on, returned to the system when
// freed (glibc's threshold otherwise grows to 32 MiB, and freed heap memory stays resident).
// Process-wide; a SpillArea with a limit calls it, and so does `iso convert` before it reads.
void keepLargeBlocksOutOfTheHeap();

// ---- Spilled arrays (specs/pipeline.md §15, "Memory").
// The per-point arrays of a conversion (SpillVector: the prepared points and their index) may live
// in temporary files mapped into memory instead of anonymous memory. While a SpillArea exists,
// such an array of at least `minBytes` is made a file of its own in the area's directory (opened
// unnamed, O_TMPFILE, so that nothing is left behind whatever ends the process; its blocks
// reserved up front, so that a full disk is an error here, not a crash later) and mapped shared.
// A pager thread then keeps the process's resident memory under `residentLimit`: it looks 500
// times a second and, when the process comes within a margin of the limit (twice the largest
// growth it has seen between two looks lately) and more than a sixteenth of the limit is file
// pages, drops every spilled array's pages from the process (MADV_DONTNEED; the data stays in the
// file and the page cache, and the next access maps it again). So the stages, which read the
// points in Morton order, keep only the neighbourhood they work on resident, and the kernel keeps
// the rest in its page cache while memory allows or writes it to disk when not.
class SpillArea {
 public:
  // One area at a time in a process (a failed check otherwise).
  SpillArea(const std::filesystem::path& directory, uint64_t residentLimit,
            uint64_t minBytes = uint64_t{2} << 20);
  ~SpillArea();
  SpillArea(const SpillArea&) = delete;
  SpillArea& operator=(const SpillArea&) = delete;
  struct Stats {
    uint64_t bytes = 0;      // spilled bytes mapped now
    uint64_t peakBytes = 0;  // the most at once since the area was made (temporary disk)
    uint64_t arrays = 0;     // spilled arrays made
    uint64_t releases = 0;   // times the pager dropped the resident pages
    uint64_t pauses = 0;     // times a thread waited in spillPause
  };
  static Stats stats();
  // The active area's resident limit (the memory a conversion is held to); 0 when none is.
  static uint64_t residentLimit();
  // Drop every spilled array's pages from the process now (what the pager does).
  static void release();
};

// Where a stage's parallel loops let the pager catch up: returns at once (one relaxed load)
// unless the process is past the resident limit while the pager drops pages; then waits until
// that drop ends. Between two looks of the pager the stages' threads can map cached pages faster
// than one thread unmaps them; a thread that waits maps none.
void spillPause();

// ---- Temporary disk (specs/pipeline.md §15).
// Every temporary file of a conversion (the points' record files, the spilled arrays) is charged
// here as it grows and refunded when it goes. While a TemporaryDiskLimit exists, a charge that
// would take the total past it throws std::runtime_error naming the place and the limit, before
// anything is written: the conversion stops with a clear error rather than filling the disk.
struct TemporaryDiskStats {
  uint64_t bytes = 0;      // charged now
  uint64_t peakBytes = 0;  // the most at once since the limit was set
  uint64_t limit = 0;      // 0: none
};
void chargeTemporaryDisk(uint64_t bytes, const std::filesystem::path& where);
void refundTemporaryDisk(uint64_t bytes) noexcept;
TemporaryDiskStats temporaryDiskStats();

class TemporaryDiskLimit {
 public:
  explicit TemporaryDiskLimit(uint64_t bytes);  // 0: none, the use is still counted
  ~TemporaryDiskLimit();
  TemporaryDiskLimit(const TemporaryDiskLimit&) = delete;
  TemporaryDiskLimit& operator=(const TemporaryDiskLimit&) = delete;
};

void* allocateSpillable(size_t bytes);
void deallocateSpillable(void* p, size_t bytes) noexcept;

// Through allocateSpillable; elements value-initialized like std::allocator's, or left
// default-initialized (numbers not zeroed) when `uninitialized`.
template <typename T, bool uninitialized = false>
struct SpillAllocator {
  using value_type = T;
  template <typename U>
  struct rebind {
    using other = SpillAllocator<U, uninitialized>;
  };
  SpillAllocator() = default;
  template <typename U>
  SpillAllocator(const SpillAllocator<U, uninitialized>&) {}
  T* allocate(size_t n) { return static_cast<T*>(allocateSpillable(n * sizeof(T))); }
  void deallocate(T* p, size_t n) noexcept { deallocateSpillable(p, n * sizeof(T)); }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    if constexpr (uninitialized && sizeof...(Args) == 0)
      ::new (static_cast<void*>(p)) U;
    else
      ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <typename U>
  bool operator==(const SpillAllocator<U, uninitialized>&) const {
    return true;
  }
};

template <typename T>
using SpillVector = std::vector<T, SpillAllocator<T>>;
template <typename T>
using UninitializedSpillVector = std::vector<T, SpillAllocator<T, true>>;

}  // namespace iso
