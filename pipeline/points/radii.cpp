// Radius of influence r_i = distance to the k-th nearest neighbour (specs/pipeline.md, "Radius of
// influence"). Exact duplicates were merged before, so no distance is zero.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <numeric>

#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

// The median of a few values (k of them): insertion sort beats selection at this size.
float smallMedian(float* values, size_t count) {
  for (size_t i = 1; i < count; ++i) {
    const float v = values[i];
    size_t j = i;
    for (; j > 0 && values[j - 1] > v; --j) values[j] = values[j - 1];
    values[j] = v;
  }
  return values[count / 2];
}

}  // namespace

float medianOf(std::span<float> values) {
  if (values.empty()) return 0.0f;
  auto middle = values.begin() + ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

Neighbors findNeighbors(const PointSet& points, const PointIndex& index, int k) {
  Neighbors result;
  const size_t n = points.size();
  result.k = int(std::min<size_t>(size_t(k), n > 0 ? n - 1 : 0));
  result.index.resize(n * size_t(result.k));
  result.distance.resize(n * size_t(result.k));
  index.allNearest(size_t(result.k), result.index.data(), result.distance.data());
  return result;
}

RadiusStats estimateRadii(PointSet& points, const Neighbors& neighbors) {
  RadiusStats stats;
  const size_t n = points.size(), k = size_t(neighbors.k);
  points.radius.assign(n, 0.0f);
  if (k == 0) return stats;
  std::vector<float> nearest(n);
  for (size_t i = 0; i < n; ++i) {
    points.radius[i] = neighbors.distance[i * k + k - 1];
    nearest[i] = neighbors.distance[i * k];
  }
  stats.spacing = medianOf(nearest);  // a median: a few sparse points do not move it
  // Clamp each radius to 4 times the median of its neighbours' so that one sparse point does not
  // spread a huge disk; keep it above a floor far below any cell.
  SpillVector<float> clamped(n);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& range) {
        std::vector<float> local(k);
        for (size_t i = range.begin(); i < range.end(); ++i) {
          float smallest = std::numeric_limits<float>::max();
          for (size_t j = 0; j < k; ++j) {
            local[j] = points.radius[neighbors.index[i * k + j]];
            smallest = std::min(smallest, local[j]);
          }
          float r = points.radius[i];
          if (r > 4.0f * smallest) r = std::min(r, 4.0f * smallMedian(local.data(), k));  // rare
          clamped[i] = std::max(r, 1e-7f);
        }
      });
  points.radius.swap(clamped);
  SpillVector<float> all = points.radius;
  stats.medianRadius = medianOf(all);
  return stats;
}

}  // namespace iso
