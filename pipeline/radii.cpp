// Radius of influence r_i = distance to the k-th nearest neighbour (specs/pipeline.md, "Radius of
// influence"). Exact duplicates were merged before, so no distance is zero; far outliers are
// found by comparing a point's radius with its neighbours'.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <numeric>

#include "knn.h"
#include "stages.h"

namespace iso {
namespace {

float medianOf(std::vector<float>& values) {
  if (values.empty()) return 0.0f;
  auto middle = values.begin() + ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

}  // namespace

Neighbors findNeighbors(const PointSet& points, const KdTree& tree, int k) {
  Neighbors result;
  const size_t n = points.size();
  result.k = int(std::min<size_t>(size_t(k), n > 0 ? n - 1 : 0));
  const size_t kk = size_t(result.k);
  result.index.resize(n * kk);
  result.distance.resize(n * kk);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, n, 1024), [&](const tbb::blocked_range<size_t>& range) {
        std::vector<uint32_t> index(kk + 1);
        std::vector<float> d2(kk + 1);
        for (size_t i = range.begin(); i < range.end(); ++i) {
          const size_t found = tree.nearest(points.position[i], kk + 1, index.data(), d2.data());
          size_t out = 0;
          for (size_t j = 0; j < found && out < kk; ++j) {
            if (index[j] == i) continue;  // the point itself
            result.index[i * kk + out] = index[j];
            result.distance[i * kk + out] = std::sqrt(d2[j]);
            ++out;
          }
          for (; out < kk;
               ++out) {  // the point was not among the first k + 1 (ties): repeat the last
            result.index[i * kk + out] = result.index[i * kk + out - 1];
            result.distance[i * kk + out] = result.distance[i * kk + out - 1];
          }
        }
      });
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
  std::vector<float> clamped(n);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& range) {
        std::vector<float> local(k);
        for (size_t i = range.begin(); i < range.end(); ++i) {
          for (size_t j = 0; j < k; ++j) local[j] = points.radius[neighbors.index[i * k + j]];
          clamped[i] = std::max(std::min(points.radius[i], 4.0f * medianOf(local)), 1e-7f);
        }
      });
  points.radius.swap(clamped);
  std::vector<float> all = points.radius;
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
                        for (size_t j = 0; j < k; ++j) {
                          const size_t other = neighbors.index[i * k + j];
                          local[j] = neighbors.distance[other * k + k - 1];
                        }
                        flagged[i] = own > 10.0f * medianOf(local) ? 1 : 0;
                      }
                    });
  return flagged;
}

void removePoints(PointSet& points, const std::vector<uint8_t>& flagged) {
  size_t out = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    if (flagged[i]) continue;
    points.position[out] = points.position[i];
    points.key[out] = points.key[i];
    points.source[out] = points.source[i];
    points.weight[out] = points.weight[i];
    if (!points.normal.empty()) points.normal[out] = points.normal[i];
    if (!points.color.empty()) points.color[out] = points.color[i];
    if (!points.radius.empty()) points.radius[out] = points.radius[i];
    ++out;
  }
  points.position.resize(out);
  points.key.resize(out);
  points.source.resize(out);
  points.weight.resize(out);
  if (!points.normal.empty()) points.normal.resize(out);
  if (!points.color.empty()) points.color.resize(out);
  if (!points.radius.empty()) points.radius.resize(out);
}

}  // namespace iso
