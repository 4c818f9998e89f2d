// Radius of influence r_i = distance to the k-th nearest neighbour (specs/pipeline.md, "Radius of
// influence"). Exact duplicates were merged before, so no distance is zero; far outliers are
// found by comparing a point's radius with its neighbours'.
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
  double spacingSum = 0.0;
  for (size_t i = 0; i < n; ++i) {
    points.radius[i] = neighbors.distance[i * k + k - 1];
    spacingSum += neighbors.distance[i * k];
  }
  stats.meanSpacing = spacingSum / double(n);
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

std::vector<uint8_t> findOutliers(const PointSet& points, const Neighbors& neighbors) {
  const size_t n = points.size(), k = size_t(neighbors.k);
  std::vector<uint8_t> flagged(n, 0);
  if (k == 0) return flagged;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<size_t>& range) {
                      std::vector<float> local(k);
                      for (size_t i = range.begin(); i < range.end(); ++i) {
                        const float own = neighbors.distance[i * k + k - 1];
                        float smallest = std::numeric_limits<float>::max();
                        for (size_t j = 0; j < k; ++j) {
                          const size_t other = neighbors.index[i * k + j];
                          local[j] = neighbors.distance[other * k + k - 1];
                          smallest = std::min(smallest, local[j]);
                        }
                        // The median is at least the smallest: most points need no median.
                        flagged[i] =
                            own > 10.0f * smallest && own > 10.0f * smallMedian(local.data(), k);
                      }
                    });
  return flagged;
}

}  // namespace iso
