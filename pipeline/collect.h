// Collecting results in parallel: f(i, out) appends what item i yields to `out`; the items are
// cut into blocks run in parallel, and the blocks' results joined in item order, so the result
// does not depend on the number of threads.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <vector>

namespace iso {

template <typename T, typename F>
std::vector<T> collectInParallel(size_t count, size_t block, const F& f) {
  std::vector<std::vector<T>> parts((count + block - 1) / block);
  tbb::parallel_for(size_t{0}, parts.size(), [&](size_t p) {
    const size_t end = std::min(count, (p + 1) * block);
    for (size_t i = p * block; i < end; ++i) f(i, parts[p]);
  });
  std::vector<T> all;
  for (const std::vector<T>& part : parts) all.insert(all.end(), part.begin(), part.end());
  return all;
}

}  // namespace iso
