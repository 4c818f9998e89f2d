#include "knn.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/common.hpp>
#include <limits>

#include "stages.h"

#include <atomic>
namespace iso {
std::atomic<uint64_t> gScanned{0}, gCand{0}, gLeaves{0};
namespace {

constexpr uint32_t kBucket = 16;  // most points in a leaf bucket
constexpr float kInfinity = std::numeric_limits<float>::infinity();

// The k best (squared distance, index) pairs seen so far, nearest first; ties keep the earlier.
struct TopK {
  float* d2;
  uint32_t* index;
  size_t k, count = 0;

  float worst() const { return count < k ? kInfinity : d2[k - 1]; }
  void push(float d, uint32_t i) {
    if (count < k) {
      ++count;
    } else if (!(d < d2[k - 1])) {
      return;
    }
    size_t j = count - 1;
    for (; j > 0 && d2[j - 1] > d; --j) {
      d2[j] = d2[j - 1];
      index[j] = index[j - 1];
    }
    d2[j] = d;
    index[j] = i;
  }
};

}  // namespace

// Squared distances from a query to runs of sorted points, written to a buffer first so that the
// loop vectorizes.
struct PointIndex::Search {
  const PointIndex& index;
  float qx, qy, qz;
  std::array<float, kBucket> buffer;

  Search(const PointIndex& i, const glm::vec3& q) : index(i), qx(q.x), qy(q.y), qz(q.z) {}

  float boxDistance2(const Node& n) const {
    const float dx = std::max({n.lo[0] - qx, 0.0f, qx - n.hi[0]});
    const float dy = std::max({n.lo[1] - qy, 0.0f, qy - n.hi[1]});
    const float dz = std::max({n.lo[2] - qz, 0.0f, qz - n.hi[2]});
    return dx * dx + dy * dy + dz * dz;
  }

  // Calls f(sorted index, squared distance) for the points [begin, end), fewer than kBucket.
  template <class F>
  void scan(uint32_t begin, uint32_t end, F&& f) {
    const float* x = index.x_.data() + begin;
    const float* y = index.y_.data() + begin;
    const float* z = index.z_.data() + begin;
    if (end <= begin) return;
    const uint32_t n = end - begin;
    gScanned.fetch_add(n, std::memory_order_relaxed);
    for (uint32_t j = 0; j < n; ++j) {
      const float dx = x[j] - qx, dy = y[j] - qy, dz = z[j] - qz;
      buffer[j] = dx * dx + dy * dy + dz * dz;
    }
    for (uint32_t j = 0; j < n; ++j) f(begin + j, buffer[j]);
  }

  template <class F>
  void scanRange(uint32_t begin, uint32_t end, F&& f) {
    for (uint32_t b = begin; b < end; b += kBucket) scan(b, std::min(end, b + kBucket), f);
  }
};

PointIndex::PointIndex(std::span<const glm::vec3> points) {
  const size_t n = points.size();
  if (n == 0) return;
  if (n >= size_t(std::numeric_limits<uint32_t>::max()))
    throw std::length_error("too many points for one index");
  // Morton keys in the unit cube when every point lies in it (frame units: the order of
  // sortByKey), else in the bounding cube.
  glm::vec3 lo = points[0], hi = points[0];
  for (const glm::vec3& p : points) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  glm::dvec3 origin(0.0);
  double size = 1.0;
  const bool unit = lo.x >= 0.0f && lo.y >= 0.0f && lo.z >= 0.0f && hi.x < 1.0f && hi.y < 1.0f &&
                    hi.z < 1.0f;
  if (!unit) {
    origin = glm::dvec3(lo);
    size = std::max({double(hi.x) - lo.x, double(hi.y) - lo.y, double(hi.z) - lo.z, 1e-30}) *
           (1.0 + 1e-6);
  }
  std::vector<uint64_t> keys(n);
  const double cells = double(1u << kMaxLevel);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        std::array<uint32_t, 3> c{};
                        for (int a = 0; a < 3; ++a)
                          c[size_t(a)] = uint32_t(std::clamp(
                              std::floor((double(points[i][a]) - origin[a]) / size * cells), 0.0,
                              cells - 1.0));
                        keys[i] = mortonEncode(c[0], c[1], c[2]);
                      }
                    });
  if (!std::is_sorted(keys.begin(), keys.end())) {
    order_ = sortedOrder(keys);
    std::vector<uint64_t> sorted(n);
    for (size_t i = 0; i < n; ++i) sorted[i] = keys[order_[i]];
    keys.swap(sorted);
  }
  x_.resize(n);
  y_.resize(n);
  z_.resize(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const glm::vec3& p = points[original(uint32_t(i))];
                        x_[i] = p.x;
                        y_[i] = p.y;
                        z_[i] = p.z;
                      }
                    });
  build(keys);
}

void PointIndex::build(const std::vector<uint64_t>& keys) {
  // Breadth first, so that children follow their parents: an octree of the keys down to
  // kMaxLevel, then halves of the remaining runs (points in one finest cell).
  std::vector<uint8_t> level;
  nodes_.push_back(Node{{}, 0, {}, uint32_t(keys.size()), 0, 0});
  level.push_back(0);
  for (size_t i = 0; i < nodes_.size(); ++i) {
    const Node node = nodes_[i];
    if (node.end - node.begin <= kBucket) continue;
    const uint32_t first = uint32_t(nodes_.size());
    const uint8_t l = level[i];
    if (l < kMaxLevel) {
      const int shift = 3 * (kMaxLevel - l - 1);
      // The octants' runs; consecutive ones that fit in a bucket together share it.
      uint32_t begin = node.begin, groupBegin = node.begin;
      while (begin < node.end) {
        const uint64_t child = keys[begin] >> shift;
        const auto end = std::partition_point(keys.begin() + begin, keys.begin() + node.end,
                                              [&](uint64_t k) { return (k >> shift) <= child; });
        const uint32_t e = uint32_t(end - keys.begin());
        if (e - groupBegin > kBucket && begin > groupBegin) {  // close the group before this run
          nodes_.push_back(Node{{}, groupBegin, {}, begin, 0, 0});
          level.push_back(uint8_t(l + 1));
          groupBegin = begin;
        }
        if (e - groupBegin > kBucket) {  // a run too large for a bucket: a node of its own
          nodes_.push_back(Node{{}, groupBegin, {}, e, 0, 0});
          level.push_back(uint8_t(l + 1));
          groupBegin = e;
        }
        begin = e;
      }
      if (groupBegin < node.end) {
        nodes_.push_back(Node{{}, groupBegin, {}, node.end, 0, 0});
        level.push_back(uint8_t(l + 1));
      }
    } else {
      const uint32_t middle = node.begin + (node.end - node.begin) / 2;
      nodes_.push_back(Node{{}, node.begin, {}, middle, 0, 0});
      nodes_.push_back(Node{{}, middle, {}, node.end, 0, 0});
      level.push_back(l);
      level.push_back(l);
    }
    nodes_[i].firstChild = first;
    nodes_[i].childCount = uint32_t(nodes_.size()) - first;
  }
  for (uint32_t i = 0; i < nodes_.size(); ++i)
    if (nodes_[i].childCount == 0) leaves_.push_back(i);
  std::sort(leaves_.begin(), leaves_.end(),
            [&](uint32_t a, uint32_t b) { return nodes_[a].begin < nodes_[b].begin; });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves_.size(), 1024),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t j = r.begin(); j < r.end(); ++j) {
                        Node& node = nodes_[leaves_[j]];
                        for (int a = 0; a < 3; ++a) {
                          node.lo[a] = kInfinity;
                          node.hi[a] = -kInfinity;
                        }
                        for (uint32_t s = node.begin; s < node.end; ++s) {
                          const float p[3] = {x_[s], y_[s], z_[s]};
                          for (int a = 0; a < 3; ++a) {
                            node.lo[a] = std::min(node.lo[a], p[a]);
                            node.hi[a] = std::max(node.hi[a], p[a]);
                          }
                        }
                      }
                    });
  for (size_t i = nodes_.size(); i-- > 0;) {
    Node& node = nodes_[i];
    if (node.childCount == 0) continue;
    for (int a = 0; a < 3; ++a) {
      node.lo[a] = kInfinity;
      node.hi[a] = -kInfinity;
    }
    for (uint32_t c = node.firstChild; c < node.firstChild + node.childCount; ++c)
      for (int a = 0; a < 3; ++a) {
        node.lo[a] = std::min(node.lo[a], nodes_[c].lo[a]);
        node.hi[a] = std::max(node.hi[a], nodes_[c].hi[a]);
      }
  }
}

size_t PointIndex::nearest(const glm::vec3& query, size_t k, uint32_t* indices,
                           float* squaredDistances) const {
  if (nodes_.empty() || k == 0) return 0;
  Search search(*this, query);
  TopK best{squaredDistances, indices, k};
  struct Entry {
    uint32_t node;
    float d2;
  };
  // Depth is at most kMaxLevel plus the halvings of one finest cell (< 32), 8 entries a level.
  std::array<Entry, 512> stack;
  size_t top = 0;
  stack[top++] = {0, search.boxDistance2(nodes_[0])};
  while (top > 0) {
    const Entry e = stack[--top];
    if (!(e.d2 < best.worst())) continue;
    const Node& node = nodes_[e.node];
    if (node.childCount == 0) {
      search.scan(node.begin, node.end, [&](uint32_t s, float d2) { best.push(d2, s); });
      continue;
    }
    // Children farthest first onto the stack, so that the nearest is searched first.
    std::array<Entry, 8> children;
    const uint32_t count = node.childCount;
    for (uint32_t c = 0; c < count; ++c) {
      Entry child{node.firstChild + c, search.boxDistance2(nodes_[node.firstChild + c])};
      uint32_t j = c;
      for (; j > 0 && children[j - 1].d2 < child.d2; --j) children[j] = children[j - 1];
      children[j] = child;
    }
    const float worst = best.worst();
    for (uint32_t c = 0; c < count; ++c)
      if (children[c].d2 < worst) stack[top++] = children[c];
  }
  for (size_t j = 0; j < best.count; ++j) indices[j] = original(indices[j]);
  return best.count;
}

void PointIndex::withinRadius(const glm::vec3& query, float radius,
                              std::vector<std::pair<uint32_t, float>>& out) const {
  out.clear();
  if (nodes_.empty() || !(radius >= 0.0f)) return;
  Search search(*this, query);
  const float r2 = radius * radius;
  std::array<uint32_t, 512> stack;
  size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (search.boxDistance2(node) > r2) continue;
    if (node.childCount == 0) {
      search.scan(node.begin, node.end, [&](uint32_t s, float d2) {
        if (d2 <= r2) out.push_back({original(s), d2});
      });
      continue;
    }
    for (uint32_t c = node.childCount; c-- > 0;) stack[top++] = node.firstChild + c;
  }
}

void PointIndex::collectLeaves(const Node& from, float radius2, std::vector<uint32_t>& out) const {
  out.clear();
  std::array<uint32_t, 512> stack;
  size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const uint32_t id = stack[--top];
    const Node& node = nodes_[id];
    float d2 = 0.0f;
    for (int a = 0; a < 3; ++a) {
      const float d = std::max({node.lo[a] - from.hi[a], 0.0f, from.lo[a] - node.hi[a]});
      d2 += d * d;
    }
    if (d2 > radius2) continue;
    if (node.childCount == 0) {
      out.push_back(id);
      continue;
    }
    for (uint32_t c = node.childCount; c-- > 0;) stack[top++] = node.firstChild + c;
  }
}

void PointIndex::allNearest(size_t k, uint32_t* indices, float* distances) const {
  const uint32_t n = uint32_t(size());
  if (k == 0 || n == 0) return;
  if (k >= n) throw std::invalid_argument("allNearest: k must be below the number of points");
  // Each bucket's points first search a window of their neighbours in Morton order (which bounds
  // their k-th distance), then the buckets within that bound.
  const uint32_t halfWindow = std::max<uint32_t>(4, uint32_t(k + 2) / 2);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, leaves_.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<float> d2(kBucket * k);
        std::vector<uint32_t> found(kBucket * k);
        std::vector<uint32_t> candidates;
        std::vector<TopK> best;
        for (size_t leafIndex = r.begin(); leafIndex < r.end(); ++leafIndex) {
          const Node& leaf = nodes_[leaves_[leafIndex]];
          const uint32_t m = leaf.end - leaf.begin;
          const uint32_t length = std::min(n, m + 2 * halfWindow);
          const uint32_t ws =
              std::min(leaf.begin > halfWindow ? leaf.begin - halfWindow : 0u, n - length);
          const uint32_t we = ws + length;
          best.clear();
          float bound = 0.0f;
          for (uint32_t q = 0; q < m; ++q) {
            TopK& b = best.emplace_back(TopK{d2.data() + q * k, found.data() + q * k, k});
            const uint32_t self = leaf.begin + q;
            Search search(*this, glm::vec3(x_[self], y_[self], z_[self]));
            search.scanRange(ws, we, [&](uint32_t s, float d) {
              if (s != self) b.push(d, s);
            });
            bound = std::max(bound, b.worst());
          }
          collectLeaves(leaf, bound, candidates);
          gCand += candidates.size(); gLeaves += 1;
          for (uint32_t q = 0; q < m; ++q) {
            TopK& b = best[q];
            const uint32_t self = leaf.begin + q;
            Search search(*this, glm::vec3(x_[self], y_[self], z_[self]));
            const auto push = [&](uint32_t s, float d) { b.push(d, s); };
            for (const uint32_t c : candidates) {
              const Node& node = nodes_[c];
              if (!(search.boxDistance2(node) < b.worst())) continue;
              search.scan(node.begin, std::min(node.end, ws), push);
              search.scan(std::max(node.begin, we), node.end, push);
            }
            const uint32_t out = original(self);
            for (size_t j = 0; j < k; ++j) {
              indices[size_t(out) * k + j] = original(b.index[j]);
              distances[size_t(out) * k + j] = std::sqrt(b.d2[j]);
            }
          }
        }
      });
}

}  // namespace iso
