// From world coordinates (double) to the frame: one global cube chosen in double, then float
// frame units in [0, 1) and Morton keys (specs/pipeline.md, "Precision").
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <numeric>

#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr double kFrameMargin = 0.05;  // of the extent, on each side

struct KeyedItem {
  uint64_t key;
  uint32_t index;
};

}  // namespace

namespace {

// Stable LSD radix sort of items[begin, end) by the key bits below `bits`, 11 bits a pass,
// skipping passes where every item has the same digit; scratch is as large as items.
void sortLow(UninitializedVector<KeyedItem>& items, UninitializedVector<KeyedItem>& scratch, size_t begin,
             size_t end, int bits) {
  const size_t n = end - begin;
  if (n < 2) return;
  if (n <= 64) {
    std::stable_sort(items.begin() + ptrdiff_t(begin), items.begin() + ptrdiff_t(end),
                     [](const KeyedItem& a, const KeyedItem& b) { return a.key < b.key; });
    return;
  }
  constexpr int kBits = 11;
  constexpr size_t kBuckets = size_t{1} << kBits;
  KeyedItem* from = items.data() + begin;
  KeyedItem* to = scratch.data() + begin;
  std::vector<size_t> count(kBuckets + 1);
  for (int shift = 0; shift < bits; shift += kBits) {
    const uint64_t mask = (uint64_t{1} << std::min(kBits, bits - shift)) - 1;
    std::fill(count.begin(), count.end(), 0);
    for (size_t i = 0; i < n; ++i) ++count[((from[i].key >> shift) & mask) + 1];
    if (std::any_of(count.begin(), count.end(), [n](size_t c) { return c == n; })) continue;
    std::partial_sum(count.begin(), count.end(), count.begin());
    for (size_t i = 0; i < n; ++i) to[count[(from[i].key >> shift) & mask]++] = from[i];
    std::swap(from, to);
  }
  if (from != items.data() + begin) std::copy(from, from + n, items.data() + begin);
}

}  // namespace

// A stable radix sort of (key, index) pairs by key: one parallel pass on the highest 11 bits in
// use (blocks of the input counted and scattered in parallel, in order), then each of those
// buckets sorted on the remaining bits by an LSD radix sort, buckets in parallel.
std::vector<uint32_t> sortedOrder(std::span<const uint64_t> keys) {
  const size_t n = keys.size();
  std::vector<uint32_t> order(n);
  if (n == 0) return order;
  if (n >= size_t(std::numeric_limits<uint32_t>::max()))
    throw std::length_error("too many points to sort in one chunk");
  uint64_t used = 0;
  for (const uint64_t k : keys) used |= k;
  const int top = 64 - std::countl_zero(used);
  constexpr int kBits = 11;
  constexpr size_t kBuckets = size_t{1} << kBits;
  const int shift = std::max(0, top - kBits);
  const auto digit = [&](uint64_t k) { return size_t(k >> shift) & (kBuckets - 1); };
  UninitializedVector<KeyedItem> items(n), scratch(n);
  constexpr size_t kBlock = size_t{1} << 16;
  const size_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<size_t> count(blocks * kBuckets, 0);
  tbb::parallel_for(size_t{0}, blocks, [&](size_t b) {
    size_t* c = count.data() + b * kBuckets;
    for (size_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) ++c[digit(keys[i])];
  });
  std::vector<size_t> bucketStart(kBuckets + 1, 0);
  size_t offset = 0;
  for (size_t d = 0; d < kBuckets; ++d) {  // offsets in (digit, block) order: stable
    bucketStart[d] = offset;
    for (size_t b = 0; b < blocks; ++b) {
      const size_t c = count[b * kBuckets + d];
      count[b * kBuckets + d] = offset;
      offset += c;
    }
  }
  bucketStart[kBuckets] = n;
  tbb::parallel_for(size_t{0}, blocks, [&](size_t b) {
    size_t* next = count.data() + b * kBuckets;
    for (size_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i)
      items[next[digit(keys[i])]++] = {keys[i], uint32_t(i)};
  });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, kBuckets, 8),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t d = r.begin(); d < r.end(); ++d)
                        sortLow(items, scratch, bucketStart[d], bucketStart[d + 1], shift);
                    });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 16),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i < r.end(); ++i) order[i] = items[i].index;
                    });
  return order;
}

namespace {

template <typename Vector>
void permute(Vector& values, const std::vector<uint32_t>& order) {
  if (values.empty()) return;
  Vector out(order.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, order.size(), 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) out[i] = values[order[i]];
  });
  values.swap(out);
}

}  // namespace

glm::vec3 unitOrZero(const glm::vec3& n) {
  const float length = glm::length(n);
  return std::isfinite(length) && length > 1e-12f ? n / length : glm::vec3(0.0f);
}

Frame chooseFrame(const PointCloud& cloud) {
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (const glm::dvec3& p : cloud.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  return chooseFrame(lo, hi);
}

Frame chooseFrame(const glm::dvec3& lo, const glm::dvec3& hi) {
  Frame frame;
  if (lo.x > hi.x) return frame;  // no points
  double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  // A degenerate extent still needs a cube; relative to the coordinates' magnitude so that the
  // cube stays representable.
  const double magnitude = std::max({std::abs(lo.x), std::abs(lo.y), std::abs(lo.z), 1.0});
  extent = std::max(extent, magnitude * 1e-9);
  frame.size = extent * (1.0 + 2.0 * kFrameMargin);
  const glm::dvec3 center = 0.5 * (lo + hi);
  for (int a = 0; a < 3; ++a) frame.origin[size_t(a)] = center[a] - 0.5 * frame.size;
  return frame;
}

uint64_t keyOf(const glm::vec3& u) {
  const double cells = double(1u << kMaxLevel);
  std::array<uint32_t, 3> c{};
  for (int a = 0; a < 3; ++a)
    c[size_t(a)] = uint32_t(std::clamp(std::floor(double(u[a]) * cells), 0.0, cells - 1.0));
  return mortonEncode(c[0], c[1], c[2]);
}

glm::dvec3 toFrame(const glm::dvec3& world, const Frame& frame) {
  return (world - glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2])) / frame.size;
}

glm::dvec3 toWorld(const glm::dvec3& frameUnits, const Frame& frame) {
  return frameUnits * frame.size + glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]);
}

glm::dvec3 gridToFrame(const GridPoint& p) {
  return glm::dvec3(p.x, p.y, p.z) * std::ldexp(1.0, -int(kMaxLevel));
}

PointSet makePointSet(const PointCloud& cloud, const Frame& frame) {
  PointSet points;
  const size_t n = cloud.size();
  points.position.resize(n);
  points.key.resize(n);
  points.weight.assign(n, 1.0f);
  points.source.resize(n);
  std::iota(points.source.begin(), points.source.end(), 0u);
  if (cloud.hasNormals()) points.normal.resize(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      points.position[i] = glm::vec3(toFrame(cloud.positions[i], frame));
      points.key[i] = keyOf(points.position[i]);
      if (cloud.hasNormals()) points.normal[i] = unitOrZero(cloud.normals[i]);
    }
  });
  if (cloud.hasColors()) points.color.assign(cloud.colors.begin(), cloud.colors.end());
  return points;
}

void sortByKey(PointSet& points) {
  const std::vector<uint32_t> order = sortedOrder(points.key);
  PointSet::forEachColumn([&](auto& column) { permute(column, order); }, points);
}

size_t mergeDuplicates(PointSet& points) {
  const size_t n = points.size();
  bool anyDuplicate = false;  // most scans have none: then nothing is copied
  for (size_t i = 1; i < n && !anyDuplicate; ++i)
    anyDuplicate = points.key[i] == points.key[i - 1] && points.position[i] == points.position[i - 1];
  if (!anyDuplicate) {
    for (size_t i = 1; i < n && !anyDuplicate; ++i)
      if (points.key[i] == points.key[i - 1])
        for (size_t j = i; j > 0 && points.key[j - 1] == points.key[i] && !anyDuplicate; --j)
          anyDuplicate = points.position[j - 1] == points.position[i];
    if (!anyDuplicate) return 0;
  }
  std::vector<uint32_t> target(n);  // the point each one merges into
  std::vector<uint32_t> run;
  for (size_t begin = 0; begin < n;) {
    size_t end = begin + 1;
    while (end < n && points.key[end] == points.key[begin]) ++end;
    run.resize(end - begin);
    std::iota(run.begin(), run.end(), uint32_t(begin));
    const auto lexLess = [&](uint32_t a, uint32_t b) {
      const glm::vec3 &p = points.position[a], &q = points.position[b];
      return std::tie(p.x, p.y, p.z, a) < std::tie(q.x, q.y, q.z, b);
    };
    std::sort(run.begin(), run.end(), lexLess);
    for (size_t i = 0; i < run.size(); ++i)
      target[run[i]] = i > 0 && points.position[run[i]] == points.position[run[i - 1]]
                           ? target[run[i - 1]]
                           : run[i];
    begin = end;
  }
  PointSet out;
  std::vector<uint32_t> slot(n);
  for (size_t i = 0; i < n; ++i) {
    if (target[i] != i) continue;
    slot[i] = uint32_t(out.position.size());
    out.position.push_back(points.position[i]);
    out.key.push_back(points.key[i]);
    out.source.push_back(points.source[i]);
    out.weight.push_back(0.0f);
    if (!points.normal.empty()) out.normal.emplace_back(0.0f);
    if (!points.color.empty()) out.color.emplace_back(0.0f);
  }
  for (size_t i = 0; i < n; ++i) {
    const uint32_t s = slot[target[i]];
    const float w = points.weight[i];
    out.weight[s] += w;
    if (!points.normal.empty()) out.normal[s] += points.normal[i] * w;
    if (!points.color.empty()) out.color[s] += points.color[i] * w;
  }
  for (size_t s = 0; s < out.size(); ++s) {
    if (!out.normal.empty()) out.normal[s] = unitOrZero(out.normal[s]);
    if (!out.color.empty()) out.color[s] /= out.weight[s];
  }
  const size_t merged = n - out.size();
  points = std::move(out);
  return merged;
}

}  // namespace iso
