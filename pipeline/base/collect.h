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
  // The blocks run 64 at a time, and each batch's results join `all` before the next runs: the
  // parts are anonymous memory, `all` may be a spilled array, and holding every part until the end
  // (as before) kept all results twice, once outside the budget (on the 50M dragon under
  // --memory 512M, most of the corner stage's 257 MiB of anonymous memory).
  constexpr size_t kBatch = 64;
  const size_t blocks = (count + block - 1) / block;
  std::vector<std::vector<T>> parts(std::min(blocks, kBatch));
  Out all;
  for (size_t first = 0; first < blocks; first += kBatch) {
    const size_t n = std::min(kBatch, blocks - first);
    tbb::parallel_for(size_t{0}, n, [&](size_t p) {
      spillPause();
      const size_t begin = (first + p) * block, end = std::min(count, begin + block);
      for (size_t i = begin; i < end; ++i) f(i, parts[p]);
    });
    for (size_t p = 0; p < n; ++p) {
      all.insert(all.end(), parts[p].begin(), parts[p].end());
      parts[p].clear();
    }
  }
  return all;
}

}  // namespace iso
