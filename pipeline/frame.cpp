// From world coordinates (double) to the frame: one global cube chosen in double, then float
// frame units in [0, 1) and Morton keys (specs/pipeline.md, "Precision").
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <numeric>

#include "stages.h"

namespace iso {
namespace {

constexpr double kFrameMargin = 0.05;  // of the extent, on each side

uint64_t keyOf(const glm::vec3& u) {
  const double cells = double(1u << kMaxLevel);
  std::array<uint32_t, 3> c{};
  for (int a = 0; a < 3; ++a)
    c[size_t(a)] = uint32_t(std::clamp(std::floor(double(u[a]) * cells), 0.0, cells - 1.0));
  return mortonEncode(c[0], c[1], c[2]);
}

struct KeyIndex {
  uint64_t key;
  uint32_t index;
};

}  // namespace

// A stable LSD radix sort of (key, index) pairs by key: 63-bit keys in 6 passes of 11 bits, the
// pairs moved together so that each pass reads them in order.
std::vector<uint32_t> sortedOrder(const std::vector<uint64_t>& keys) {
  const size_t n = keys.size();
  std::vector<KeyIndex> items(n), scratch(n);
  for (size_t i = 0; i < n; ++i) items[i] = {keys[i], uint32_t(i)};
  constexpr int kBits = 11;
  constexpr size_t kBuckets = size_t{1} << kBits;
  for (int shift = 0; shift < 64; shift += kBits) {
    std::vector<size_t> count(kBuckets + 1, 0);
    for (const KeyIndex& item : items) ++count[((item.key >> shift) & (kBuckets - 1)) + 1];
    if (std::any_of(count.begin(), count.end(), [n](size_t c) { return c == n; })) continue;  // one digit
    std::partial_sum(count.begin(), count.end(), count.begin());
    for (const KeyIndex& item : items) scratch[count[(item.key >> shift) & (kBuckets - 1)]++] = item;
    items.swap(scratch);
  }
  std::vector<uint32_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = items[i].index;
  return order;
}

namespace {

template <typename T>
void permute(std::vector<T>& values, const std::vector<uint32_t>& order) {
  if (values.empty()) return;
  std::vector<T> out(order.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, order.size(), 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) out[i] = values[order[i]];
  });
  values.swap(out);
}

glm::vec3 unitOrZero(const glm::vec3& n) {
  const float length = glm::length(n);
  return std::isfinite(length) && length > 1e-12f ? n / length : glm::vec3(0.0f);
}

}  // namespace

Frame chooseFrame(const PointCloud& cloud) {
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (const glm::dvec3& p : cloud.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  Frame frame;
  if (cloud.positions.empty()) return frame;
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

glm::dvec3 toFrame(const glm::dvec3& world, const Frame& frame) {
  return (world - glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2])) / frame.size;
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
  if (cloud.hasColors()) points.color = cloud.colors;
  return points;
}

void sortByKey(PointSet& points) {
  const std::vector<uint32_t> order = sortedOrder(points.key);
  permute(points.position, order);
  permute(points.normal, order);
  permute(points.color, order);
  permute(points.weight, order);
  permute(points.radius, order);
  permute(points.key, order);
  permute(points.source, order);
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
