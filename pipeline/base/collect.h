// Collecting results in parallel: f(i, out) appends what item i yields to `out`; the items are
// cut into blocks run in parallel, and the blocks' results joined in item order, so the result
// does not depend on the number of threads.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <vector>

#include "pipeline/base/buffers.h"

namespace iso {

template <typename T, typename Out = std::vector<T>, typename F>
Out collectInParallel(size_t count, size_t block, const F& f) {
  std::vector<std::vector<T>> parts((count + block - 1) / block);
  tbb::parallel_for(size_t{0}, parts.size(), [&](size_t p) {
    spillPause();
    const size_t end = std::min(count, (p + 1) * block);
    for (size_t i = p * block; i < end; ++i) f(i, parts[p]);
  });
  size_t total = 0;
  for (const std::vector<T>& part : parts) total += part.size();
  Out all;
  all.reserve(total);
  for (std::vector<T>& part : parts) {
    all.insert(all.end(), part.begin(), part.end());
    part = {};
  }
  return all;
}

}  // namespace iso
