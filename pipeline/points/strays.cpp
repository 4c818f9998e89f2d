// Stray points (specs/pipeline.md, "Stray points"): isolated returns, small groups far from
// everything (birds, multipath) and sparse dust. A point is a stray when its k-th neighbour is
// far beyond what the scan's robust spacing allows, or when its group (the points it joins
// through near k-NN edges) is too small to make a surface. Both are decided the same way in core
// and chunk by chunk: the groups are a union-find over the edges each point adds from its own
// exact k-NN list, the threshold a median and MAD over all points.
#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

// An edge i→j joins a surface when no longer than this many times the smaller of the two
// points' k-th neighbour distances: within a sampled surface every k-NN edge is shorter than
// both, while the edges from a stray group to the surface below it are many times the surface's.
constexpr float kEdgeReach = 3.0f;

enum class StrayKind : uint8_t { SmallGroup, Sparse };

}  // namespace

PointGroups::PointGroups(size_t ids) : parent_(ids) {
  std::iota(parent_.begin(), parent_.end(), 0u);
}

uint32_t PointGroups::root(uint32_t id) {
  uint32_t r = id;
  while (parent_[r] != r) r = parent_[r];
  while (parent_[id] != r) id = std::exchange(parent_[id], r);  // path compression
  return r;
}

void PointGroups::join(uint32_t a, uint32_t b) {
  a = root(a);
  b = root(b);
  if (a == b) return;
  if (a > b) std::swap(a, b);  // the smaller id is the root: the partition decides, not the order
  parent_[b] = a;
}

void PointGroups::joinNeighbors(const Neighbors& neighbors, uint32_t begin, uint32_t end,
                                uint32_t first, SpillVector<std::array<uint32_t, 2>>& outside) {
  const size_t k = size_t(neighbors.k);
  if (k == 0) return;
  for (uint32_t i = begin; i < end; ++i) {
    const float own = neighbors.distance[size_t(i) * k + k - 1];
    for (size_t e = 0; e < k; ++e) {
      const uint32_t j = neighbors.index[size_t(i) * k + e];
      const float reach = kEdgeReach * std::min(own, neighbors.distance[size_t(j) * k + k - 1]);
      if (!(neighbors.distance[size_t(i) * k + e] <= reach)) continue;
      if (j >= begin && j < end)
        join(first + (i - begin), first + (j - begin));
      else
        outside.push_back({first + (i - begin), j});
    }
  }
}

float sparseThreshold(std::span<const float> kth) {
  if (kth.empty()) return std::numeric_limits<float>::max();
  SpillVector<float> logs(kth.size());
  for (size_t i = 0; i < kth.size(); ++i) logs[i] = std::log(std::max(kth[i], 1e-30f));
  const float median = medianOf(logs);
  for (float& v : logs) v = std::abs(v - median);
  const double sigma = 1.4826 * double(medianOf(logs));  // the MAD as a normal's σ
  const double factor =
      std::max(double(StrayRule::kSparseFactor), std::exp(StrayRule::kSparseSigmas * sigma));
  return float(std::exp(double(median)) * factor);
}

Strays flagStrays(std::span<const float> kth, PointGroups& groups, uint32_t groupPoints) {
  const size_t n = kth.size();
  Strays out;
  out.flagged.assign(n, 0);
  const float threshold = sparseThreshold(kth);
  // Each point's group is named by its root; a group's size is counted at its root. Only the
  // groups that can be sparse strays (at least groupPoints points, less than half of all) need
  // their median k-th distance: their members, sorted, make runs whose middles are the medians.
  SpillVector<uint32_t> rootOf(n), size(n, 0);
  for (size_t i = 0; i < n; ++i) ++size[rootOf[i] = groups.root(uint32_t(i))];
  const auto isHalf = [&](size_t count) { return 2 * count >= n; };  // never the half of the scan
  SpillVector<std::pair<uint32_t, float>> members;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t count = size[rootOf[i]];
    if (count >= groupPoints && !isHalf(count)) members.push_back({rootOf[i], kth[i]});
  }
  std::sort(members.begin(), members.end());
  std::vector<std::pair<uint32_t, StrayKind>> verdicts;  // by root, for the groups that are strays
  for (size_t i = 0; i < n; ++i)
    if (rootOf[i] == i && size[i] < groupPoints && !isHalf(size[i]))
      verdicts.emplace_back(uint32_t(i), StrayKind::SmallGroup);
  for (size_t a = 0, b = 0; a < members.size(); a = b) {
    while (b < members.size() && members[b].first == members[a].first) ++b;
    if (members[a + (b - a) / 2].second > threshold)
      verdicts.emplace_back(members[a].first, StrayKind::Sparse);
  }
  std::sort(verdicts.begin(), verdicts.end());
  for (size_t i = 0; i < n; ++i) {
    const uint32_t root = rootOf[i];
    const auto it = std::lower_bound(verdicts.begin(), verdicts.end(),
                                     std::pair<uint32_t, StrayKind>{root, StrayKind{}});
    if (it == verdicts.end() || it->first != root) continue;
    out.flagged[i] = 1;
    ++(it->second == StrayKind::Sparse ? out.sparse : out.grouped);
  }
  return out;
}

Strays findStrays(size_t n, const Neighbors& neighbors, uint32_t groupPoints) {
  const size_t k = size_t(neighbors.k);
  if (k == 0) return {std::vector<uint8_t>(n, 0)};
  std::vector<float> kth(n);
  for (size_t i = 0; i < n; ++i) kth[i] = neighbors.distance[i * k + k - 1];
  PointGroups groups(n);
  SpillVector<std::array<uint32_t, 2>> outside;  // none: every neighbour is among the n
  groups.joinNeighbors(neighbors, 0, uint32_t(n), 0, outside);
  return flagStrays(kth, groups, groupPoints);
}

PointCloud withoutFlagged(const PointCloud& cloud, const Frame& frame, const PointSet& points,
                          std::span<const uint8_t> flagged, PointCloud* removed) {
  StrayPositions strays;
  for (size_t i = 0; i < points.size(); ++i)
    if (flagged[i]) strays.add(points.position[i]);
  strays.seal();
  PointCloud out;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const bool isStray = strays.contains(glm::vec3(toFrame(cloud.positions[i], frame)));
    if (!isStray || removed) appendPoint(isStray ? *removed : out, cloud, i);
  }
  return out;
}

PointCloud withoutStrays(const PointCloud& cloud, int k, uint32_t groupPoints) {
  if (cloud.size() < 2) return cloud;
  const Frame frame = chooseFrame(cloud);
  PointSet points = makePointSet(cloud, frame);
  sortByKey(points);
  mergeDuplicates(points);
  const PointIndex index(points.position);
  const Strays strays = findStrays(points.size(), findNeighbors(points, index, k), groupPoints);
  if (strays.sparse + strays.grouped == 0) return cloud;
  return withoutFlagged(cloud, frame, points, strays.flagged);
}

StrayPositions::Bits StrayPositions::bitsOf(const glm::vec3& p) {
  return {std::bit_cast<uint32_t>(p.x), std::bit_cast<uint32_t>(p.y), std::bit_cast<uint32_t>(p.z)};
}

void StrayPositions::seal() {
  std::sort(bits_.begin(), bits_.end());
  bits_.erase(std::unique(bits_.begin(), bits_.end()), bits_.end());
}

bool StrayPositions::contains(const glm::vec3& p) const {
  return !bits_.empty() && std::binary_search(bits_.begin(), bits_.end(), bitsOf(p));
}

}  // namespace iso
