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
#include <limits>
#include <map>
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

// Orientation blocks: the coarsest Morton cells holding at most maxPoints points, as ranges of the
// key-sorted points. They depend only on the points, so an out-of-core conversion, whatever its
// chunks, orients in the same blocks.
std::vector<std::array<uint32_t, 2>> orientationBlocks(const PointSet& points, size_t maxPoints) {
  const size_t n = points.size();
  std::vector<std::array<uint32_t, 2>> blocks;
  if (n <= maxPoints || points.key.size() != n ||
      !std::is_sorted(points.key.begin(), points.key.end()))
    return {{0u, uint32_t(n)}};
  const auto split = [&](auto&& self, uint32_t begin, uint32_t end, int level) -> void {
    if (end - begin <= maxPoints || level == kMaxLevel) {
      blocks.push_back({begin, end});
      return;
    }
    const int shift = 3 * (kMaxLevel - level - 1);
    const uint64_t prefix = points.key[begin] >> (shift + 3) << (shift + 3);
    uint32_t childBegin = begin;
    for (uint64_t child = 0; child < 8; ++child) {
      const uint64_t limit = prefix + ((child + 1) << shift);  // first key of the next child
      const auto childEnd = uint32_t(
          std::lower_bound(points.key.begin() + childBegin, points.key.begin() + end, limit) -
          points.key.begin());
      if (childEnd > childBegin) self(self, childBegin, childEnd, level + 1);
      childBegin = childEnd;
    }
  };
  split(split, 0, uint32_t(n), 0);
  return blocks;
}

// Union-find over components with the parity (flip or not) of each relative to its set's root,
// and whether the set's orientation is fixed by input normals.
class ParityForest {
 public:
  explicit ParityForest(size_t n) : parent_(n), parity_(n, 0), fixed_(n, 0) {
    std::iota(parent_.begin(), parent_.end(), 0u);
  }
  void fix(uint32_t c) { fixed_[c] = 1; }
  // The root of c, with c's parity relative to it.
  uint32_t find(uint32_t c, uint8_t& parity) {
    parity = 0;
    while (parent_[c] != c) {
      parity ^= parity_[c];
      c = parent_[c];
    }
    return c;
  }
  // Require flip(a) ^ flip(b) == differ; ignored when both sets are fixed or already joined.
  void join(uint32_t a, uint32_t b, uint8_t differ) {
    uint8_t pa = 0, pb = 0;
    uint32_t ra = find(a, pa), rb = find(b, pb);
    if (ra == rb || (fixed_[ra] && fixed_[rb])) return;
    if (fixed_[ra]) {  // hang the free set below the fixed one
      std::swap(ra, rb);
      std::swap(pa, pb);
    }
    parent_[ra] = rb;
    parity_[ra] = uint8_t(pa ^ pb ^ differ);
  }
  bool isFixed(uint32_t root) const { return fixed_[root] != 0; }

 private:
  std::vector<uint32_t> parent_;
  std::vector<uint8_t> parity_, fixed_;
};

// Propagation inside one block, by Prim's algorithm over the block's own edges: first from the
// input normals (one fixed component), then from the highest unreached point of each further
// part, whose normal is turned up. Component ids are from `nextComponent`, in block order.
struct BlockComponents {
  std::vector<uint8_t> anchored;  // per component of the block: holds input normals
  std::vector<float> seedHeight;  // per component: height of its seed (its highest point)
};

BlockComponents propagateInBlock(PointSet& points, const Graph& g,
                                 const std::vector<uint8_t>& wasEstimated, uint32_t begin,
                                 uint32_t end, uint32_t firstComponent,
                                 std::vector<uint32_t>& component) {
  BlockComponents found;
  BucketQueue queue;
  const auto inBlock = [&](uint32_t j) { return j >= begin && j < end; };
  const auto visit = [&](uint32_t i, uint32_t c) {
    component[i] = c;
    for (uint32_t e = g.offset[i]; e < g.offset[i + 1]; ++e) {
      const uint32_t j = g.target[e];
      if (inBlock(j) && component[j] == kNoNode)
        queue.push(1.0f - std::abs(glm::dot(points.normal[i], points.normal[j])), i, j);
    }
  };
  const auto drain = [&](uint32_t c) {
    uint32_t from = 0, to = 0;
    while (queue.pop(from, to)) {
      if (component[to] != kNoNode) continue;
      if (glm::dot(points.normal[from], points.normal[to]) < 0.0f)
        points.normal[to] = -points.normal[to];
      visit(to, c);
    }
  };
  uint32_t next = firstComponent;
  bool anyAnchor = false;
  for (uint32_t i = begin; i < end; ++i)  // input normals anchor the orientation
    if (!wasEstimated[i]) {
      visit(i, next);
      anyAnchor = true;
    }
  if (anyAnchor) {
    drain(next++);
    found.anchored.push_back(1);
    found.seedHeight.push_back(std::numeric_limits<float>::lowest());
  }
  std::vector<uint32_t> byHeight(end - begin);
  std::iota(byHeight.begin(), byHeight.end(), begin);
  std::stable_sort(byHeight.begin(), byHeight.end(), [&](uint32_t a, uint32_t b) {
    return points.position[a].z > points.position[b].z;
  });
  for (uint32_t seed : byHeight) {
    if (component[seed] != kNoNode) continue;
    if (points.normal[seed].z < 0.0f)
      points.normal[seed] = -points.normal[seed];  // the top faces up
    visit(seed, next);
    drain(next++);
    found.anchored.push_back(0);
    found.seedHeight.push_back(points.position[seed].z);
  }
  return found;
}

// Consistent orientation block by block (blocks propagate independently, in parallel), then whole
// components flipped to agree across block boundaries: a maximum spanning forest over the
// components, weighted by the summed agreement n_i·n_j of the edges between them, rooted at the
// components holding input normals, else at the component with the highest seed (the one whose
// "top faces up" rule is the most trustworthy). With one block this is Prim's algorithm over the
// whole graph.
void propagate(PointSet& points, const Graph& g, const std::vector<uint8_t>& wasEstimated,
               size_t blockPoints) {
  const size_t n = points.size();
  const std::vector<std::array<uint32_t, 2>> blocks = orientationBlocks(points, blockPoints);
  std::vector<uint32_t> component(n, kNoNode);
  // Component ids per block start at the block's first point: unique without coordination.
  std::vector<BlockComponents> found(blocks.size());
  tbb::parallel_for(size_t{0}, blocks.size(), [&](size_t b) {
    const auto [begin, end] = blocks[b];
    found[b] = propagateInBlock(points, g, wasEstimated, begin, end, begin, component);
  });
  if (blocks.size() == 1) return;

  // Dense component ids: block b's components are blocks[b][0] + 0, 1, ...
  std::vector<uint32_t> firstDense(blocks.size() + 1, 0);
  for (size_t b = 0; b < blocks.size(); ++b)
    firstDense[b + 1] = firstDense[b] + uint32_t(found[b].anchored.size());
  std::vector<uint32_t> blockOfPoint(n);
  for (size_t b = 0; b < blocks.size(); ++b)
    std::fill(blockOfPoint.begin() + blocks[b][0], blockOfPoint.begin() + blocks[b][1],
              uint32_t(b));
  const auto dense = [&](uint32_t i) {
    const uint32_t b = blockOfPoint[i];
    return firstDense[b] + (component[i] - blocks[b][0]);
  };
  // Agreement between components, summed in fixed point so that the order does not matter.
  std::map<std::pair<uint32_t, uint32_t>, int64_t> agreement;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t e = g.offset[i]; e < g.offset[i + 1]; ++e) {
      const uint32_t j = g.target[e];
      if (j <= i || blockOfPoint[j] == blockOfPoint[i]) continue;
      const auto a = dense(i), b = dense(j);
      const auto key = std::minmax(a, b);
      agreement[{key.first, key.second}] +=
          std::llround(double(glm::dot(points.normal[i], points.normal[j])) * 65536.0);
    }
  std::vector<std::pair<std::pair<uint32_t, uint32_t>, int64_t>> edges(agreement.begin(),
                                                                       agreement.end());
  std::stable_sort(edges.begin(), edges.end(), [](const auto& x, const auto& y) {
    return std::llabs(x.second) > std::llabs(y.second);
  });
  const uint32_t components = firstDense.back();
  ParityForest forest(components);
  std::vector<float> seedHeight(components);
  for (size_t b = 0; b < blocks.size(); ++b)
    for (size_t c = 0; c < found[b].anchored.size(); ++c) {
      if (found[b].anchored[c]) forest.fix(firstDense[b] + uint32_t(c));
      seedHeight[firstDense[b] + c] = found[b].seedHeight[c];
    }
  for (const auto& [pair, sum] : edges)
    if (sum != 0) forest.join(pair.first, pair.second, sum < 0 ? 1 : 0);
  // A free set keeps the orientation of its highest seed.
  std::vector<uint32_t> highest(components, kNoNode);
  for (uint32_t c = 0; c < components; ++c) {
    uint8_t parity = 0;
    const uint32_t root = forest.find(c, parity);
    if (highest[root] == kNoNode || seedHeight[c] > seedHeight[highest[root]]) highest[root] = c;
  }
  std::vector<uint8_t> flip(components, 0);
  for (uint32_t c = 0; c < components; ++c) {
    uint8_t parity = 0, rootParity = 0;
    const uint32_t root = forest.find(c, parity);
    if (!forest.isFixed(root)) forest.find(highest[root], rootParity);
    flip[c] = parity ^ rootParity;
  }
  for (uint32_t i = 0; i < n; ++i)
    if (flip[dense(i)]) points.normal[i] = -points.normal[i];
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
                          const std::vector<uint8_t>& wasEstimated, size_t blockPoints) {
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
  propagate(points, symmetricGraph(neighbors, points.size()), wasEstimated, blockPoints);
  return stats;
}

}  // namespace iso
