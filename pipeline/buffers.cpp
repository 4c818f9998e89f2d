#include "buffers.h"

#include <sys/mman.h>

#include <algorithm>
#include <cstdlib>

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

}  // namespace iso
