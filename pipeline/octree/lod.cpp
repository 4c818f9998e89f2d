// Level of detail (specs/pipeline.md, "Level of detail"): internal nodes carry corners too, so any
// cut through the tree renders as a coarser surface. A node at level ℓ is evaluated with
// σ >= kLodSigmaFraction · (its edge), a low-pass matched to its size, from proxies: the points
// averaged over cells two levels finer than the node (weighted mean position, normal and colour;
// weight scaled by how well the normals agree), which bounds the work per corner at every level.
// Where cells that fine hold fewer than 4 points on average, proxies would save nothing: those
// levels are evaluated from the points themselves.
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>

#include <cmath>
#include <functional>
#include <glm/geometric.hpp>
#include <map>
#include <memory>
#include <optional>

#include "pipeline/base/buffers.h"
#include "pipeline/base/options.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr float kLodSigmaFraction = 0.5f;  // σ floor of level-of-detail corners, in node edges
constexpr int kProxyLevels = 2;            // proxies are cells this many levels below the node

// The weighted sums of the points in one cell: Σw, Σw p, Σw n, Σw r, Σw c.
struct CellSums {
  double weight = 0.0;
  glm::dvec3 position{0.0};
  glm::vec3 normal{0.0f}, color{0.0f};
  float radius = 0.0f;
};

// Proxies of the points of each occupied cell at `level` (points sorted by key): the weighted
// mean position, normal, radius and colour of the cell's points; the weight scaled by how well
// the normals agree; no keys (only the signed distance reads proxies). In parallel over parts cut
// at cell boundaries; each part counts its cells first and then fills its own range, and a cell's
// sums live only while its proxy is made.
PointSet proxiesAt(const PointSet& points, int level) {
  const size_t count = points.size();
  const auto keyAt = [&](size_t i) { return points.key[i]; };
  const int shift = 3 * (kMaxLevel - level);
  constexpr size_t kPart = size_t{1} << 16;
  const size_t parts = std::max<size_t>(1, count / kPart);
  std::vector<size_t> cut(parts + 1, count);
  cut[0] = 0;
  for (size_t p = 1; p < parts; ++p) {  // move each cut to the start of a cell (binary search)
    const size_t at = p * count / parts;
    const uint64_t cell = keyAt(at - 1) >> shift;
    size_t lo = at, hi = count;  // the first index in [at, count) past `cell`
    while (lo < hi) {
      const size_t mid = lo + (hi - lo) / 2;
      if ((keyAt(mid) >> shift) == cell)
        lo = mid + 1;
      else
        hi = mid;
    }
    cut[p] = std::max(lo, cut[p - 1]);
  }
  const auto forEachCell = [&](size_t p, const auto& f) {
    for (size_t i = cut[p]; i < cut[p + 1];) {
      const size_t first = i;
      const uint64_t cell = keyAt(i) >> shift;
      while (i < cut[p + 1] && (keyAt(i) >> shift) == cell) ++i;
      f(first, i);
    }
  };
  std::vector<size_t> offset(parts + 1, 0);
  tbb::parallel_for(size_t{0}, parts,
                    [&](size_t p) { forEachCell(p, [&](size_t, size_t) { ++offset[p + 1]; }); });
  for (size_t p = 0; p < parts; ++p) offset[p + 1] += offset[p];
  const size_t m = offset[parts];
  const bool colors = points.hasColors();
  PointSet proxies;
  proxies.position.resize(m);
  proxies.normal.resize(m);
  proxies.weight.resize(m);
  proxies.radius.resize(m);
  if (colors) proxies.color.resize(m);
  tbb::parallel_for(size_t{0}, parts, [&](size_t p) {
    size_t at = offset[p];
    forEachCell(p, [&](size_t begin, size_t end) {
      CellSums c;
      for (size_t i = begin; i < end; ++i) {
        const double w = points.weight[i];
        c.weight += w;
        c.position += w * glm::dvec3(points.position[i]);
        c.normal += float(w) * points.normal[i];
        c.radius += float(w) * points.radius[i];
        if (colors) c.color += float(w) * points.color[i];
      }
      const size_t k = at++;
      const double coherence = glm::length(glm::dvec3(c.normal)) / c.weight;  // 1: all agree
      proxies.position[k] = glm::vec3(c.position / c.weight);
      proxies.normal[k] = coherence > 1e-6 ? glm::normalize(c.normal) : glm::vec3(0.0f);
      proxies.weight[k] = float(c.weight * std::max(coherence, 1e-3));
      proxies.radius[k] = float(double(c.radius) / c.weight);
      if (colors) proxies.color[k] = glm::vec3(glm::dvec3(c.color) / c.weight);
    });
  });
  return proxies;
}

// The number of occupied cells at every level of points sorted by key: from the level at which
// each pair of neighbours in key order first differs.
std::array<size_t, kMaxLevel + 1> occupiedCells(const PointSet& points) {
  const size_t n = points.size();
  const auto partAt = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(1, std::max<size_t>(n, 1), 1 << 16),
      std::array<size_t, kMaxLevel + 1>{},
      [&](const tbb::blocked_range<size_t>& r, std::array<size_t, kMaxLevel + 1> c) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const uint64_t differ = points.key[i] ^ points.key[i - 1];
          if (differ == 0) continue;
          const int bit = 63 - std::countl_zero(differ);  // highest differing bit
          ++c[size_t(kMaxLevel - bit / 3)];               // the level where they part
        }
        return c;
      },
      [](std::array<size_t, kMaxLevel + 1> a, const std::array<size_t, kMaxLevel + 1>& b) {
        for (size_t l = 0; l <= kMaxLevel; ++l) a[l] += b[l];
        return a;
      });
  std::array<size_t, kMaxLevel + 1> cells{};
  size_t total = n > 0 ? 1 : 0;
  for (size_t l = 0; l <= kMaxLevel; ++l) cells[l] = total += partAt[l];
  return cells;
}

}  // namespace

Key128 lodKey(uint8_t level, const GridPoint& p) {
  return {p.x | uint64_t(p.y) << 32, p.z | uint64_t(level) << 32};
}

uint32_t LodField::find(uint8_t level, const GridPoint& p) const {
  return index.find(lodKey(level, p));  // kNone is kNoNode
}

GridPoint LodField::point(uint32_t entry) const {
  const Key128& k = index.key(entry);
  return {uint32_t(k.a), uint32_t(k.a >> 32), uint32_t(k.b)};
}

LodProxyLevels lodProxyLevels(const PointSet& points) {
  // Proxies where they hold 4 points or more on average; at finer levels the points themselves.
  const std::array<size_t, kMaxLevel + 1> cells = occupiedCells(points);
  LodProxyLevels proxyLevel{};
  for (int level = 0; level <= kMaxLevel; ++level) {
    const int proxy = std::min(level + kProxyLevels, int(kMaxLevel));
    proxyLevel[size_t(level)] =
        4 * cells[size_t(proxy)] > points.size() ? int8_t{-1} : int8_t(proxy);
  }
  return proxyLevel;
}

namespace {

using LevelCorners = std::map<int, SpillVector<std::pair<uint32_t, GridPoint>>>;  // entry, point

// Evaluates the corners of every level: those of levels without proxies first (each corner's
// value depends on its level alone), so that the points' signed distance can go (pointsSdfDone)
// before any proxies are made; then the proxies of one level at a time, each summed from the
// points, made when a node level first needs them and freed when the next needs another.
// evaluate(sdf, entry, point, minSigma) stores one corner's value.
template <typename Evaluate>
void evaluateLevels(const LevelCorners& byLevel, const PointSet& points,
                    const SdfEvaluator& pointsSdf, const BuildOptions& options,
                    const LodProxyLevels& proxyLevels, const std::function<void()>& pointsSdfDone,
                    const Evaluate& evaluate) {
  const auto evaluateLevel = [&](int level, const SdfEvaluator& sdf) {
    const SpillVector<std::pair<uint32_t, GridPoint>>& corners = byLevel.at(level);
    const float minSigma = kLodSigmaFraction * float(std::ldexp(1.0, -level));
    tbb::parallel_for(tbb::blocked_range<size_t>(0, corners.size(), 256),
                      [&](const tbb::blocked_range<size_t>& r) {
                        spillPause();
                        for (size_t i = r.begin(); i < r.end(); ++i)
                          evaluate(sdf, corners[i].first, corners[i].second, minSigma);
                      });
  };
  for (const auto& [level, corners] : byLevel)
    if (proxyLevels[size_t(level)] < 0 && !corners.empty()) evaluateLevel(level, pointsSdf);
  if (pointsSdfDone) pointsSdfDone();
  int madeLevel = -1;
  PointSet proxies;
  std::unique_ptr<PointIndex> proxyIndex;
  std::unique_ptr<SdfEvaluator> proxySdf;
  for (const auto& [level, corners] : byLevel) {
    const int proxyLevel = proxyLevels[size_t(level)];
    if (proxyLevel < 0 || corners.empty()) continue;
    if (proxyLevel != madeLevel) {
      proxySdf.reset();
      proxyIndex.reset();
      proxies = PointSet{};
      proxies = proxiesAt(points, proxyLevel);
      proxyIndex = std::make_unique<PointIndex>(proxies.position);
      proxySdf =
          std::make_unique<SdfEvaluator>(proxies, *proxyIndex, options.smoothing, options.fit);
      madeLevel = proxyLevel;
    }
    evaluateLevel(level, *proxySdf);
  }
}

constexpr double kUnit = 1.0 / double(uint64_t{1} << kMaxLevel);  // a grid step in the frame

glm::dvec3 framePoint(const GridPoint& p) {
  return {double(p.x) * kUnit, double(p.y) * kUnit, double(p.z) * kUnit};
}

}  // namespace

// The serial walks over every node map the nodes' spilled pages as fast as they read them: they
// wait for the pager (spillPause) every so many nodes, as the parallel stages do between blocks.
constexpr size_t kNodesBetweenPauses = size_t{1} << 16;

LodField sampleLodCorners(const Octree& tree, const PointSet& points, const SdfEvaluator& pointsSdf,
                          const BuildOptions& options, const std::function<void()>& pointsSdfDone,
                          const CellCut& cut, const SpillVector<LodSample>* known,
                          const LodProxyLevels* proxyLevels) {
  LodField field;
  // A part's stretch: room for 4 corners an internal node (8 a node, each shared by a few).
  std::vector<size_t> internalOf(cut.firstCell.size(), 0);
  if (!cut.firstCell.empty()) {
    field.index.cutByCells(cut, 0);
    for (size_t i = 0; i < tree.nodes.size(); ++i) {
      if (i % kNodesBetweenPauses == 0) spillPause();
      const OctreeNode& node = tree.nodes[i];
      if (const size_t p = cut.partOfNode(node.level, node.key);
          node.kind == NodeKind::Internal && p != CellCut::kNoPart)
        ++internalOf[p];
    }
  }
  size_t part = CellCut::kNoPart;
  LevelCorners byLevel;
  for (size_t i = 0; i < tree.nodes.size(); ++i) {
    if (i % kNodesBetweenPauses == 0) spillPause();
    const OctreeNode& node = tree.nodes[i];
    if (node.kind != NodeKind::Internal) continue;
    if (!cut.firstCell.empty()) {
      const size_t p = cut.partOfNode(node.level, node.key);
      if (p != part) {
        if (p == CellCut::kNoPart)
          field.index.closeParts();
        else
          field.index.openPart(p, 4 * internalOf[p]);
        part = p;
      }
    }
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(node.level, node.key, c);
      const auto [entry, inserted] = field.index.insert(lodKey(node.level, p));
      if (!inserted) continue;
      field.value.emplace_back();
      byLevel[node.level].push_back({entry, p});
    }
  }
  if (known != nullptr && !known->empty()) {
    // The first sample of each entry (in parallel: the smallest sample number wins), then only
    // the corners without one are evaluated.
    constexpr uint32_t kNoSample = ~uint32_t{0};
    SpillVector<uint32_t> first(field.value.size(), kNoSample);
    const auto entryOf = [&](size_t i) { return field.index.find((*known)[i].key); };
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, known->size(), 4096),
        [&](const tbb::blocked_range<size_t>& r) {
          spillPause();
          for (size_t i = r.begin(); i < r.end(); ++i) {
            const uint32_t e = entryOf(i);
            if (e == CellKeyIndex::kNone) continue;
            std::atomic_ref<uint32_t> slot(first[e]);
            uint32_t seen = slot.load(std::memory_order_relaxed);
            while (uint32_t(i) < seen && !slot.compare_exchange_weak(seen, uint32_t(i))) {
            }
          }
        });
    tbb::parallel_for(tbb::blocked_range<size_t>(0, first.size(), 4096),
                      [&](const tbb::blocked_range<size_t>& r) {
                        spillPause();
                        for (size_t e = r.begin(); e < r.end(); ++e)
                          if (first[e] != kNoSample) field.value[e] = (*known)[first[e]].value;
                      });
    for (auto& [level, corners] : byLevel)
      field.fromSamples +=
          std::erase_if(corners, [&](const auto& c) { return first[c.first] != kNoSample; });
  }
  evaluateLevels(byLevel, points, pointsSdf, options,
                 proxyLevels != nullptr ? *proxyLevels : lodProxyLevels(points), pointsSdfDone,
                 [&](const SdfEvaluator& sdf, uint32_t entry, const GridPoint& p, float minSigma) {
                   field.value[entry] = sdf.evaluate(framePoint(p), minSigma);
                 });
  return field;
}

SpillVector<LodSample> sampleLodCornersWithin(
    const Octree& tree, const PointSet& points, const SdfEvaluator& pointsSdf,
    const BuildOptions& options, const LodProxyLevels& proxyLevels, uint8_t minLevel,
    const std::function<bool(uint8_t level, uint64_t key)>& owned, double reach) {
  std::vector<Key128> keys;
  for (const OctreeNode& node : tree.nodes)
    if (node.kind == NodeKind::Internal && node.level >= minLevel && owned(node.level, node.key))
      for (int c = 0; c < kCorners; ++c)
        keys.push_back(lodKey(node.level, cornerPoint(node.level, node.key, c)));
  const auto order = [](const Key128& x, const Key128& y) {
    return x.b >> 32 != y.b >> 32 ? x.b >> 32 < y.b >> 32 : (x.b != y.b ? x.b < y.b : x.a < y.a);
  };
  std::sort(keys.begin(), keys.end(), order);
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  LevelCorners byLevel;
  for (uint32_t i = 0; i < keys.size(); ++i) {
    const Key128& k = keys[i];
    byLevel[int(k.b >> 32)].push_back(
        {i, GridPoint{uint32_t(k.a), uint32_t(k.a >> 32), uint32_t(k.b)}});
  }
  std::vector<std::optional<CornerSample>> values(keys.size());
  evaluateLevels(byLevel, points, pointsSdf, options, proxyLevels, {},
                 [&](const SdfEvaluator& sdf, uint32_t i, const GridPoint& p, float minSigma) {
                   values[i] = sdf.evaluateWithin(framePoint(p), minSigma, reach);
                 });
  SpillVector<LodSample> samples;
  for (size_t i = 0; i < keys.size(); ++i)
    if (values[i]) samples.push_back({keys[i], *values[i]});
  return samples;
}

float nodePatchError(const Octree& tree, const PointSet& points, const LodField& lod, uint32_t id) {
  const OctreeNode& node = tree.nodes[id];
  Patch patch(node.level, node.key);
  for (int c = 0; c < kCorners; ++c)
    patch.distance[size_t(c)] =
        lod.value[lod.find(node.level, cornerPoint(node.level, node.key, c))].distance;
  return float(patch.maxPointDistance(points, node.pointBegin, node.pointEnd));
}

}  // namespace iso
