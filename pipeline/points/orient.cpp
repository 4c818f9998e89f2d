// Consistent orientation of normals (specs/pipeline.md, "Normals"). Estimated normals have no
// sign; they are oriented by propagation along a minimum spanning tree of the k-NN graph with
// edge cost 1 - |n_i·n_j| (Hoppe et al. 1992), starting from points whose input normal is known,
// else from the highest point of each connected part (whose normal points up), or all upward
// (--orient up, aerial scans). The tree grows inside orientation blocks; whole components are
// then flipped to agree across blocks. Input normals that contradict nearly all of their
// neighbours are flipped first.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <map>
#include <numeric>

#include "pipeline/base/options.h"
#include "pipeline/points/points.h"

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
  std::vector<float> seedVote;  // per component: its points times its seed normal's z
};

BlockComponents propagateInBlock(PointSet& points, const Graph& g,
                                 const std::vector<uint8_t>& wasEstimated, uint32_t begin,
                                 uint32_t end, uint32_t firstComponent,
                                 std::vector<uint32_t>& component) {
  BlockComponents found;
  BucketQueue queue;
  const auto inBlock = [&](uint32_t j) { return j >= begin && j < end; };
  size_t reached = 0;
  const auto visit = [&](uint32_t i, uint32_t c) {
    component[i] = c;
    ++reached;
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
    found.seedVote.push_back(0.0f);  // fixed: takes no vote
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
    const size_t before = reached;
    visit(seed, next);
    drain(next++);
    found.anchored.push_back(0);
    found.seedVote.push_back(float(reached - before) * points.normal[seed].z);
  }
  return found;
}

constexpr int kRepairPasses = 4;

// Flip input normals that oppose at least 80% of their neighbours' (and at least 3 of them). Only
// neighbours near the point's tangent plane count (within 30° of it): on two sheets closer than
// the radius the other sheet's points lie along the normal, and their opposite normals are right.
// One pass; returns how many flipped, and adds those among [countBegin, countEnd) to `counted`.
size_t repairFlipped(PointSet& points, const Neighbors& neighbors,
                     const std::vector<uint8_t>& wasEstimated, uint32_t countBegin,
                     uint32_t countEnd, size_t& counted) {
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
      counted += i >= countBegin && i < countEnd ? 1 : 0;
    }
  return count;
}

}  // namespace

OrientationBlocks orientationBlocks(const PointSet& points, size_t maxPoints, uint32_t begin,
                                     uint32_t end, int level) {
  OrientationBlocks blocks;
  const bool sorted = points.key.size() == points.size() &&
                      std::is_sorted(points.key.begin() + begin, points.key.begin() + end);
  const auto split = [&](auto&& self, uint32_t first, uint32_t last, int depth) -> void {
    if (last - first <= maxPoints || depth == kMaxLevel || !sorted) {
      blocks.push_back({first, last});
      return;
    }
    const int shift = 3 * (kMaxLevel - depth - 1);
    const uint64_t prefix = points.key[first] >> (shift + 3) << (shift + 3);
    uint32_t childBegin = first;
    for (uint64_t child = 0; child < 8; ++child) {
      const uint64_t limit = prefix + ((child + 1) << shift);  // first key of the next child
      const auto childEnd = uint32_t(
          std::lower_bound(points.key.begin() + childBegin, points.key.begin() + last, limit) -
          points.key.begin());
      if (childEnd > childBegin) self(self, childBegin, childEnd, depth + 1);
      childBegin = childEnd;
    }
  };
  if (end > begin) split(split, begin, end, level);
  return blocks;
}

size_t repairFlippedNormals(PointSet& points, const Neighbors& neighbors,
                            const std::vector<uint8_t>& wasEstimated, uint32_t countBegin,
                            uint32_t countEnd) {
  // Repeat: a flipped normal among several flipped neighbours is outvoted only once some of them
  // are repaired.
  size_t total = 0;
  for (int pass = 0; pass < kRepairPasses; ++pass) {
    if (repairFlipped(points, neighbors, wasEstimated, countBegin, countEnd, total) == 0) break;
  }
  return total;
}

void propagateInBlocks(PointSet& points, const Neighbors& neighbors,
                       const std::vector<uint8_t>& wasEstimated, const OrientationBlocks& blocks,
                       OrientationComponents& components) {
  const Graph g = symmetricGraph(neighbors, points.size());
  // Component ids per block start at the block's first point: unique without coordination.
  std::vector<uint32_t> local(points.size(), kNoNode);
  std::vector<BlockComponents> found(blocks.size());
  tbb::parallel_for(size_t{0}, blocks.size(), [&](size_t b) {
    const auto [begin, end] = blocks[b];
    found[b] = propagateInBlock(points, g, wasEstimated, begin, end, begin, local);
  });
  // Dense ids, continuing those already in `components`: block by block, seed by seed.
  for (size_t b = 0; b < blocks.size(); ++b) {
    const auto first = uint32_t(components.anchored.size());
    for (uint32_t i = blocks[b][0]; i < blocks[b][1]; ++i)
      components.of[i] = first + (local[i] - blocks[b][0]);
    components.anchored.insert(components.anchored.end(), found[b].anchored.begin(),
                               found[b].anchored.end());
    components.seedVote.insert(components.seedVote.end(), found[b].seedVote.begin(),
                                 found[b].seedVote.end());
  }
}

void alignComponents(std::span<glm::vec3> normals, const OrientationComponents& components,
                     std::span<const uint32_t> neighborIndex, size_t k) {
  alignComponents(normals, components, {}, neighborIndex, k);
}

void alignComponents(std::span<glm::vec3> normals, const OrientationComponents& components,
                     std::span<const uint32_t> from, std::span<const uint32_t> neighborIndex,
                     size_t k) {
  const size_t n = k > 0 ? neighborIndex.size() / k : 0;  // points whose edges are given
  const auto pointOf = [&](size_t m) { return from.empty() ? m : size_t(from[m]); };
  const auto count = uint32_t(components.anchored.size());
  // Agreement between components over every k-NN edge (i → j) joining two of them, summed in
  // fixed point so that the order does not matter. Points of different components are in
  // different blocks: inside a block, propagation reaches every neighbour.
  using Agreement = std::map<std::pair<uint32_t, uint32_t>, int64_t>;
  tbb::enumerable_thread_specific<Agreement> partial;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 16),
                    [&](const tbb::blocked_range<size_t>& r) {
                      Agreement& local = partial.local();
                      for (size_t m = r.begin(); m < r.end(); ++m)
                        for (size_t e = 0; e < k; ++e) {
                          const size_t i = pointOf(m);
                          const uint32_t j = neighborIndex[m * k + e];
                          const uint32_t a = components.of[i], b = components.of[j];
                          if (a == b) continue;
                          local[std::minmax(a, b)] += std::llround(
                              double(glm::dot(normals[i], normals[j])) * 65536.0);
                        }
                    });
  Agreement agreement;
  for (const Agreement& local : partial)
    for (const auto& [pair, sum] : local) agreement[pair] += sum;
  std::vector<std::pair<std::pair<uint32_t, uint32_t>, int64_t>> edges(agreement.begin(),
                                                                       agreement.end());
  std::stable_sort(edges.begin(), edges.end(), [](const auto& x, const auto& y) {
    return std::llabs(x.second) > std::llabs(y.second);
  });
  ParityForest forest(count);
  for (uint32_t c = 0; c < count; ++c)
    if (components.anchored[c]) forest.fix(c);
  for (const auto& [pair, sum] : edges)
    if (sum != 0) forest.join(pair.first, pair.second, sum < 0 ? 1 : 0);
  // A free set takes the sign its components vote for: each component's own "top faces up" guess,
  // weighted by its size and by how vertical its seed's normal is (a horizontal one tells
  // nothing). Steadier than any single seed when the relative signs are only weakly known.
  std::vector<double> vote(count, 0.0);
  for (uint32_t c = 0; c < count; ++c) {
    uint8_t parity = 0;
    const uint32_t root = forest.find(c, parity);
    vote[root] += parity ? -double(components.seedVote[c]) : double(components.seedVote[c]);
  }
  std::vector<uint8_t> flip(count, 0);
  for (uint32_t c = 0; c < count; ++c) {
    uint8_t parity = 0;
    const uint32_t root = forest.find(c, parity);
    const uint8_t rootParity = !forest.isFixed(root) && vote[root] < 0.0 ? 1 : 0;
    flip[c] = parity ^ rootParity;
  }
  for (size_t i = 0; i < normals.size(); ++i)
    if (flip[components.of[i]]) normals[i] = -normals[i];
}

NormalStats orientNormals(PointSet& points, const Neighbors& neighbors, OrientMode mode,
                          const std::vector<uint8_t>& wasEstimated, size_t blockPoints) {
  NormalStats stats;
  stats.estimated = size_t(std::count(wasEstimated.begin(), wasEstimated.end(), uint8_t{1}));
  stats.flipped = repairFlippedNormals(points, neighbors, wasEstimated);
  if (stats.estimated == 0) return stats;
  if (mode == OrientMode::Up) {
    orientUp(points, wasEstimated, 0, uint32_t(points.size()));
    return stats;
  }
  // Consistent orientation block by block (blocks propagate independently, in parallel), then
  // whole components flipped to agree across block boundaries. With one block this is Prim's
  // algorithm over the whole graph.
  const OrientationBlocks blocks =
      orientationBlocks(points, blockPoints, 0, uint32_t(points.size()), 0);
  OrientationComponents components;
  components.of.assign(points.size(), kNoNode);
  propagateInBlocks(points, neighbors, wasEstimated, blocks, components);
  if (blocks.size() > 1)
    alignComponents(points.normal, components, neighbors.index, size_t(neighbors.k));
  return stats;
}

void orientUp(PointSet& points, const std::vector<uint8_t>& wasEstimated, uint32_t begin,
              uint32_t end) {
  for (uint32_t i = begin; i < end; ++i)
    if (wasEstimated[i] && points.normal[i].z < 0.0f) points.normal[i] = -points.normal[i];
}

}  // namespace iso
