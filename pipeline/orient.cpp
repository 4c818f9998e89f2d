// Consistent orientation of normals (specs/pipeline.md, "Normals"). Estimated normals have no
// sign; they are oriented by propagation along a minimum spanning tree of the k-NN graph with
// edge cost 1 - |n_i·n_j| (Hoppe et al. 1992), starting from points whose input normal is known,
// else from the highest point of each connected part (whose normal points up), or all upward
// (--orient up, aerial scans). Input normals that contradict nearly all of their neighbours are
// flipped first.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <numeric>

#include "stages.h"

namespace iso {
namespace {

// The k-NN graph made symmetric, in compressed rows.
struct Graph {
  std::vector<uint32_t> offset, target;
};

Graph symmetricGraph(const Neighbors& neighbors, size_t n) {
  const size_t k = size_t(neighbors.k);
  std::vector<uint32_t> degree(n + 1, 0);
  for (size_t i = 0; i < n; ++i)
    for (size_t j = 0; j < k; ++j) {
      ++degree[i + 1];
      ++degree[neighbors.index[i * k + j] + 1];
    }
  Graph g;
  g.offset.resize(n + 1);
  std::partial_sum(degree.begin(), degree.end(), g.offset.begin());
  g.target.resize(g.offset[n]);
  std::vector<uint32_t> fill(g.offset.begin(), g.offset.end() - 1);
  for (size_t i = 0; i < n; ++i)
    for (size_t j = 0; j < k; ++j) {
      const uint32_t other = neighbors.index[i * k + j];
      g.target[fill[i]++] = other;
      g.target[fill[other]++] = uint32_t(i);
    }
  return g;
}

// A priority queue of edges with costs in [0, 1] quantized to buckets: Prim's algorithm in linear
// time; ties pop last-in first-out, which keeps the order deterministic.
class BucketQueue {
 public:
  static constexpr int kBuckets = 256;
  void push(float cost, uint32_t from, uint32_t to) {
    const int b = std::clamp(int(cost * (kBuckets - 1) + 0.5f), 0, kBuckets - 1);
    buckets_[size_t(b)].push_back({from, to});
    lowest_ = std::min(lowest_, b);
    ++size_;
  }
  bool pop(uint32_t& from, uint32_t& to) {
    if (size_ == 0) return false;
    while (buckets_[size_t(lowest_)].empty()) ++lowest_;
    auto& bucket = buckets_[size_t(lowest_)];
    from = bucket.back()[0];
    to = bucket.back()[1];
    bucket.pop_back();
    --size_;
    return true;
  }

 private:
  std::array<std::vector<std::array<uint32_t, 2>>, kBuckets> buckets_;
  int lowest_ = kBuckets - 1;
  size_t size_ = 0;
};

void propagate(PointSet& points, const Graph& g, const std::vector<uint8_t>& wasEstimated) {
  const size_t n = points.size();
  std::vector<uint8_t> visited(n, 0);
  BucketQueue queue;
  const auto visit = [&](uint32_t i) {
    visited[i] = 1;
    for (uint32_t e = g.offset[i]; e < g.offset[i + 1]; ++e) {
      const uint32_t j = g.target[e];
      if (!visited[j])
        queue.push(1.0f - std::abs(glm::dot(points.normal[i], points.normal[j])), i, j);
    }
  };
  const auto drain = [&] {
    uint32_t from = 0, to = 0;
    while (queue.pop(from, to)) {
      if (visited[to]) continue;
      if (glm::dot(points.normal[from], points.normal[to]) < 0.0f)
        points.normal[to] = -points.normal[to];
      visit(to);
    }
  };
  for (uint32_t i = 0; i < n; ++i)  // input normals anchor the orientation
    if (!wasEstimated[i]) visit(i);
  drain();
  std::vector<uint32_t> byHeight(n);
  std::iota(byHeight.begin(), byHeight.end(), 0u);
  std::stable_sort(byHeight.begin(), byHeight.end(), [&](uint32_t a, uint32_t b) {
    return points.position[a].z > points.position[b].z;
  });
  for (uint32_t seed : byHeight) {
    if (visited[seed]) continue;
    if (points.normal[seed].z < 0.0f)
      points.normal[seed] = -points.normal[seed];  // the top faces up
    visit(seed);
    drain();
  }
}

// Flip input normals that oppose at least 80% of their neighbours' (and at least 3 of them). Only
// neighbours near the point's tangent plane count (within 30° of it): on two sheets closer than
// the radius the other sheet's points lie along the normal, and their opposite normals are right.
size_t repairFlipped(PointSet& points, const Neighbors& neighbors,
                     const std::vector<uint8_t>& wasEstimated) {
  const size_t n = points.size(), k = size_t(neighbors.k);
  std::vector<uint8_t> flip(n, 0);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& range) {
        for (size_t i = range.begin(); i < range.end(); ++i) {
          if (wasEstimated[i]) continue;
          size_t opposing = 0, known = 0;
          for (size_t j = 0; j < k; ++j) {
            const uint32_t other = neighbors.index[i * k + j];
            if (wasEstimated[other]) continue;
            const glm::vec3 offset = points.position[other] - points.position[i];
            if (std::abs(glm::dot(offset, points.normal[i])) > 0.5f * glm::length(offset)) continue;
            ++known;
            opposing += glm::dot(points.normal[i], points.normal[other]) < -0.5f ? 1 : 0;
          }
          flip[i] = opposing >= 3 && opposing * 5 >= known * 4;
        }
      });
  size_t count = 0;
  for (size_t i = 0; i < n; ++i)
    if (flip[i]) {
      points.normal[i] = -points.normal[i];
      ++count;
    }
  return count;
}

}  // namespace

NormalStats orientNormals(PointSet& points, const Neighbors& neighbors, OrientMode mode,
                          const std::vector<uint8_t>& wasEstimated) {
  NormalStats stats;
  stats.estimated = size_t(std::count(wasEstimated.begin(), wasEstimated.end(), uint8_t{1}));
  // Repeat: a flipped normal among several flipped neighbours is outvoted only once some of them
  // are repaired.
  for (int pass = 0; pass < 4; ++pass) {
    const size_t flipped = repairFlipped(points, neighbors, wasEstimated);
    stats.flipped += flipped;
    if (flipped == 0) break;
  }
  if (stats.estimated == 0) return stats;
  if (mode == OrientMode::Up) {
    for (size_t i = 0; i < points.size(); ++i)
      if (wasEstimated[i] && points.normal[i].z < 0.0f) points.normal[i] = -points.normal[i];
    return stats;
  }
  propagate(points, symmetricGraph(neighbors, points.size()), wasEstimated);
  return stats;
}

}  // namespace iso
