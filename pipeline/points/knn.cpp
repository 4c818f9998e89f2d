#include "pipeline/points/knn.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/common.hpp>
#include <limits>

#include "iso/check.h"
#include "pipeline/base/progress.h"
#include "pipeline/points/points.h"

#include <bit>

namespace iso {
namespace {

constexpr uint32_t kBucket = 16;  // most points in a leaf bucket
constexpr float kInfinity = std::numeric_limits<float>::infinity();

// The k best (squared distance, index) pairs seen so far, nearest first. Ties go to the lower
// index, so that the answer does not depend on the order in which points are seen.
struct TopK {
  float* d2;
  uint32_t* index;
  size_t k, count = 0;

  float worst() const { return count < k ? kInfinity : d2[k - 1]; }
  static bool before(float da, uint32_t ia, float db, uint32_t ib) {
    return da < db || (da == db && ia < ib);
  }
  void push(float d, uint32_t i) {
    if (count < k) {
      ++count;
    } else if (!before(d, i, d2[k - 1], index[k - 1])) {
      return;
    }
    size_t j = count - 1;
    for (; j > 0 && before(d, i, d2[j - 1], index[j - 1]); --j) {
      d2[j] = d2[j - 1];
      index[j] = index[j - 1];
    }
    d2[j] = d;
    index[j] = i;
  }
  // push() for indices that only grow: a tie never goes before an earlier point.
  void pushGrowing(float d, uint32_t i) {
    if (count < k) {
      ++count;
    } else if (!(d < d2[k - 1])) {
      return;
    }
    size_t j = count - 1;
    for (; j > 0 && d < d2[j - 1]; --j) {
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
  origin_ = origin;
  cellsPerUnit_ = double(1u << kMaxLevel) / size;
  UninitializedSpillVector<uint64_t> keys(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i < r.end(); ++i) keys[i] = keyOf(points[i]);
                    });
  if (!std::is_sorted(keys.begin(), keys.end())) {
    order_ = sortedOrder(keys);
    UninitializedSpillVector<uint64_t> sorted(n);
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

uint64_t PointIndex::keyOf(const glm::vec3& p) const {
  constexpr double kLast = double((1u << kMaxLevel) - 1);
  std::array<uint32_t, 3> c{};
  for (int a = 0; a < 3; ++a)
    c[size_t(a)] =
        uint32_t(std::clamp(std::floor((double(p[a]) - origin_[a]) * cellsPerUnit_), 0.0, kLast));
  return mortonEncode(c[0], c[1], c[2]);
}

// The children of a node: [bound[c], bound[c + 1]) for c < count.
struct PointIndex::Children {
  uint32_t count = 0;
  std::array<uint32_t, 9> bound{};
  std::array<bool, 8> cell{};  // whether child c is a whole octant
};

PointIndex::Children PointIndex::split(std::span<const uint64_t> keys, const Node& node,
                                       uint8_t l) {
  Children out;
  const auto add = [&](uint32_t begin, uint32_t end, bool cell) {
    out.bound[out.count] = begin;
    out.bound[out.count + 1] = end;
    out.cell[out.count] = cell;
    ++out.count;
  };
  if (l >= kMaxLevel) {  // points in one finest cell: halves by count
    const uint32_t middle = node.begin + (node.end - node.begin) / 2;
    add(node.begin, middle, false);
    add(middle, node.end, false);
    return out;
  }
  // The octants' runs; consecutive ones that fit in a bucket together share it. A node of one
  // octant is that octant's cell.
  const int shift = 3 * (kMaxLevel - l - 1);
  uint32_t begin = node.begin, groupBegin = node.begin, runs = 0;
  while (begin < node.end) {
    const uint64_t child = keys[begin] >> shift;
    const auto end = std::partition_point(keys.begin() + begin, keys.begin() + node.end,
                                          [&](uint64_t k) { return (k >> shift) <= child; });
    const uint32_t e = uint32_t(end - keys.begin());
    if (e - groupBegin > kBucket && begin > groupBegin) {  // close the group before this run
      add(groupBegin, begin, runs == 1);
      groupBegin = begin;
      runs = 0;
    }
    ++runs;
    if (e - groupBegin > kBucket) {  // a run too large for a bucket: a node of its own
      add(groupBegin, e, true);
      groupBegin = e;
      runs = 0;
    }
    begin = e;
  }
  if (groupBegin < node.end) add(groupBegin, node.end, runs == 1);
  return out;
}

uint32_t PointIndex::startNode(const glm::vec3& lo, const glm::vec3& hi, float pad) const {
  // The deepest level whose cell holds the whole box (grown by pad and a relative margin for the
  // rounding of float distances), then the deepest node that is such a cell.
  constexpr double kLast = double((1u << kMaxLevel) - 1);
  int level = kMaxLevel;
  std::array<uint32_t, 3> low{};
  for (int a = 0; a < 3; ++a) {
    const double margin = double(pad) * (1.0 + 1e-5) + 1e-6 * std::abs(double(lo[a])) + 1e-30;
    const auto cell = [&](double v) {
      return uint32_t(std::clamp(std::floor((v - origin_[a]) * cellsPerUnit_), 0.0, kLast));
    };
    low[size_t(a)] = cell(double(lo[a]) - margin);
    const uint32_t high = cell(double(hi[a]) + margin);
    const uint32_t differ = low[size_t(a)] ^ high;
    if (differ != 0) level = std::min(level, kMaxLevel - (32 - std::countl_zero(differ)));
  }
  const uint64_t key = mortonEncode(low[0], low[1], low[2]);
  for (int l = level; l > 0; --l)
    if (const uint32_t* node = cells_.find(cellCode(uint8_t(l), key >> (3 * (kMaxLevel - l)))))
      return *node;
  return 0;
}

void PointIndex::build(std::span<const uint64_t> keys) {
  // Level by level, so that children follow their parents: an octree of the keys down to
  // kMaxLevel, then halves of the remaining runs (points in one finest cell). The children of a
  // level's nodes are found in parallel, then appended in order.
  std::vector<uint8_t> level = {0};
  nodes_.push_back(Node{{}, 0, {}, uint32_t(keys.size()), 0, 0});
  cells_.insert(cellCode(0, 0), 0);
  std::vector<uint32_t> frontier = {0};
  std::vector<Children> children;
  while (!frontier.empty()) {
    children.assign(frontier.size(), Children{});
    tbb::parallel_for(tbb::blocked_range<size_t>(0, frontier.size(), 256),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t f = r.begin(); f < r.end(); ++f)
                          children[f] = split(keys, nodes_[frontier[f]], level[frontier[f]]);
                      });
    std::vector<uint32_t> next;
    for (size_t f = 0; f < frontier.size(); ++f) {
      const Children& c = children[f];
      Node& parent = nodes_[frontier[f]];
      const uint8_t l = level[frontier[f]];
      parent.firstChild = uint32_t(nodes_.size());
      parent.childCount = c.count;
      const uint8_t childLevel = l < kMaxLevel ? uint8_t(l + 1) : l;
      for (uint32_t j = 0; j < c.count; ++j) {
        const uint32_t id = uint32_t(nodes_.size());
        if (c.cell[j])
          cells_.insert(cellCode(childLevel, keys[c.bound[j]] >> (3 * (kMaxLevel - childLevel))),
                        id);
        nodes_.push_back(Node{{}, c.bound[j], {}, c.bound[j + 1], 0, 0});
        level.push_back(childLevel);
        if (c.bound[j + 1] - c.bound[j] > kBucket) next.push_back(id);
      }
    }
    frontier.swap(next);
  }
  for (uint32_t i = 0; i < nodes_.size(); ++i)
    if (nodes_[i].childCount == 0) leaves_.push_back(i);
  tbb::parallel_sort(leaves_.begin(), leaves_.end(),
                     [&](uint32_t a, uint32_t b) { return nodes_[a].begin < nodes_[b].begin; });
  leafKey_.resize(leaves_.size());
  for (size_t j = 0; j < leaves_.size(); ++j) leafKey_[j] = keys[nodes_[leaves_[j]].begin];
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
  // The bucket where the query's Morton key falls, and its neighbours in Morton order, first:
  // they bound the k-th distance, so the tree search below visits few nodes.
  const uint32_t n = uint32_t(size());
  const size_t leaf = size_t(
      std::max<ptrdiff_t>(std::upper_bound(leafKey_.begin(), leafKey_.end(), keyOf(query)) -
                              leafKey_.begin() - 1,
                          0));
  const uint32_t halfWindow = uint32_t(std::min<size_t>(k, kBucket));
  const Node& home = nodes_[leaves_[leaf]];
  const uint32_t ws = home.begin > halfWindow ? home.begin - halfWindow : 0;
  const uint32_t we = std::min(n, home.end + halfWindow);
  const auto push = [&](uint32_t s, float d2) { best.push(d2, s); };
  search.scanRange(ws, we, push);
  struct Entry {
    uint32_t node;
    float d2;
  };
  // Depth is at most kMaxLevel plus the halvings of one finest cell (< 32), 8 entries a level.
  std::array<Entry, 512> stack;
  size_t top = 0;
  const uint32_t start = startNode(query, query, std::sqrt(best.worst()));
  stack[top++] = {start, search.boxDistance2(nodes_[start])};
  while (top > 0) {
    const Entry e = stack[--top];
    if (!(e.d2 <= best.worst())) continue;  // (equal: a tie with a lower index may be there)
    const Node& node = nodes_[e.node];
    if (node.childCount == 0) {
      search.scan(node.begin, std::min(node.end, ws), push);
      search.scan(std::max(node.begin, we), node.end, push);
      continue;
    }
    // Children farthest first onto the stack, so that the nearest is searched first.
    const float worst = best.worst();
    std::array<Entry, 8> children;
    uint32_t count = 0;
    for (uint32_t c = node.firstChild; c < node.firstChild + node.childCount; ++c) {
      const Entry child{c, search.boxDistance2(nodes_[c])};
      if (!(child.d2 <= worst)) continue;
      uint32_t j = count++;
      for (; j > 0 && children[j - 1].d2 < child.d2; --j) children[j] = children[j - 1];
      children[j] = child;
    }
    for (uint32_t c = 0; c < count; ++c) stack[top++] = children[c];
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
  stack[top++] = startNode(query, query, radius);
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

void PointIndex::collectLeaves(const float lo[3], const float hi[3], float radius2,
                               std::vector<uint32_t>& out) const {
  out.clear();
  if (nodes_.empty()) return;
  std::array<uint32_t, 512> stack;
  size_t top = 0;
  stack[top++] = startNode(glm::vec3(lo[0], lo[1], lo[2]), glm::vec3(hi[0], hi[1], hi[2]),
                           std::sqrt(radius2));
  while (top > 0) {
    const uint32_t id = stack[--top];
    const Node& node = nodes_[id];
    float d2 = 0.0f;
    for (int a = 0; a < 3; ++a) {
      const float d = std::max({node.lo[a] - hi[a], 0.0f, lo[a] - node.hi[a]});
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
  ISO_CHECK(k < n);  // k must be below the number of points
  // For each bucket: a radius R that likely holds every point's k nearest (the previous bucket's
  // largest k-th distance, or for the first bucket of a run the k-th distances within a window
  // of Morton neighbours), the points of every bucket within R of this one gathered once, and
  // every point's k nearest among those within R. A point with fewer than k points within R
  // makes the bucket start over with the window's bound, which always holds: the answer is exact
  // and, with ties resolved by index, the same on any number of threads.
  const uint32_t halfWindow = std::max<uint32_t>(4, uint32_t(k + 2) / 2);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, leaves_.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<float> bestD2(k), gx, gy, gz, d2;
        std::vector<uint32_t> bestIndex(k), gi, candidates, selected;
        float radius2 = 0.0f;  // R²; 0: not known yet
        uint64_t counted = 0;  // points done, for progress
        float previous = kInfinity;  // the k-th squared distance of the point before
        for (size_t leafIndex = r.begin(); leafIndex < r.end(); ++leafIndex) {
          const Node& leaf = nodes_[leaves_[leafIndex]];
          bool fromWindow = radius2 == 0.0f;
          for (;;) {
            if (fromWindow) {  // every point has k points within its window's k-th distance
              const uint32_t length = std::min(n, leaf.end - leaf.begin + 2 * halfWindow);
              const uint32_t ws =
                  std::min(leaf.begin > halfWindow ? leaf.begin - halfWindow : 0u, n - length);
              radius2 = 0.0f;
              for (uint32_t self = leaf.begin; self < leaf.end; ++self) {
                TopK best{bestD2.data(), bestIndex.data(), k};
                Search search(*this, glm::vec3(x_[self], y_[self], z_[self]));
                search.scanRange(ws, ws + length, [&](uint32_t s, float d) {
                  if (s != self) best.push(d, s);
                });
                radius2 = std::max(radius2, best.worst());
              }
            }
            collectLeaves(leaf.lo, leaf.hi, radius2, candidates);
            gx.clear();
            gy.clear();
            gz.clear();
            gi.clear();
            for (const uint32_t c : candidates)
              for (uint32_t s = nodes_[c].begin; s < nodes_[c].end; ++s) {
                gx.push_back(x_[s]);
                gy.push_back(y_[s]);
                gz.push_back(z_[s]);
                gi.push_back(s);
              }
            d2.resize(gx.size());
            selected.resize(gx.size());
            float largest = 0.0f;
            bool complete = true;
            for (uint32_t self = leaf.begin; self < leaf.end && complete; ++self) {
              const float qx = x_[self], qy = y_[self], qz = z_[self];
              const size_t count = gx.size();
              for (size_t j = 0; j < count; ++j) {
                const float dx = gx[j] - qx, dy = gy[j] - qy, dz = gz[j] - qz;
                d2[j] = dx * dx + dy * dy + dz * dz;
              }
              // The candidates within a threshold, compacted without branches: the previous
              // point's k-th distance (grown a little) when that is below R, else R.
              TopK best{bestD2.data(), bestIndex.data(), k};
              float threshold = std::min(radius2, previous * 1.21f);
              for (int pass = 0; pass < 2 && best.count < k; ++pass) {
                if (pass == 1) {
                  if (threshold == radius2) break;
                  threshold = radius2;
                  best.count = 0;
                }
                size_t within = 0;
                for (size_t j = 0; j < count; ++j) {
                  selected[within] = uint32_t(j);
                  within += d2[j] <= threshold;
                }
                for (size_t j = 0; j < within; ++j)
                  if (gi[selected[j]] != self) best.pushGrowing(d2[selected[j]], gi[selected[j]]);
              }
              if (best.count < k) {
                complete = false;
                break;
              }
              previous = best.d2[k - 1];
              largest = std::max(largest, previous);
              const uint32_t out = original(self);
              for (size_t j = 0; j < k; ++j) {
                indices[size_t(out) * k + j] = original(best.index[j]);
                distances[size_t(out) * k + j] = std::sqrt(best.d2[j]);
              }
            }
            if (complete) {
              radius2 = largest * 1.5625f;  // (1.25 R)² for the next bucket
              break;
            }
            ISO_CHECK(!fromWindow);  // the window bound holds
            fromWindow = true;
          }
          counted += leaf.end - leaf.begin;
        }
        progressAdvance(counted);  // once per range: one shared counter, many threads
      });
}

}  // namespace iso
