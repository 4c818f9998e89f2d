// Level of detail (specs/pipeline.md, "Level of detail"): internal nodes carry corners too, so any
// cut through the tree renders as a coarser surface. A node at level ℓ is evaluated with
// σ >= kLodSigmaFraction · (its edge), a low-pass matched to its size, from proxies: the points
// averaged over cells two levels finer than the node (weighted mean position, normal and colour;
// weight scaled by how well the normals agree), which bounds the work per corner at every level.
#include <tbb/parallel_for.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <memory>

#include "knn.h"
#include "stages.h"

namespace iso {
namespace {

constexpr float kLodSigmaFraction = 0.5f;  // σ floor of level-of-detail corners, in node edges
constexpr int kProxyLevels = 2;            // proxies are cells this many levels below the node

// Aggregate points (sorted by key) into one proxy per occupied cell at `level`.
PointSet makeProxies(const PointSet& points, int level) {
  PointSet proxies;
  const int shift = 3 * (kMaxLevel - level);
  for (size_t begin = 0; begin < points.size();) {
    const uint64_t cell = points.key[begin] >> shift;
    size_t end = begin;
    double weight = 0.0, radius = 0.0;
    glm::dvec3 position(0.0), normal(0.0), color(0.0);
    for (; end < points.size() && (points.key[end] >> shift) == cell; ++end) {
      const double w = points.weight[end];
      weight += w;
      position += w * glm::dvec3(points.position[end]);
      normal += w * glm::dvec3(points.normal[end]);
      radius += w * points.radius[end];
      if (points.hasColors()) color += w * glm::dvec3(points.color[end]);
    }
    const double coherence = glm::length(normal) / weight;  // 1: all normals agree
    proxies.position.push_back(glm::vec3(position / weight));
    proxies.normal.push_back(coherence > 1e-6 ? glm::vec3(glm::normalize(normal))
                                              : glm::vec3(0.0f));
    proxies.weight.push_back(float(weight * std::max(coherence, 1e-3)));
    proxies.radius.push_back(float(radius / weight));
    proxies.key.push_back(points.key[begin]);
    if (points.hasColors()) proxies.color.push_back(glm::vec3(color / weight));
    begin = end;
  }
  return proxies;
}

// Evaluators over proxies for each proxy level, built on first use.
class ProxyPyramid {
 public:
  ProxyPyramid(const PointSet& points, const BuildOptions& options)
      : points_(points), options_(options) {}

  const SdfEvaluator& forNodeLevel(int level) {
    const int proxyLevel = std::min(level + kProxyLevels, int(kMaxLevel));
    auto it = levels_.find(proxyLevel);
    if (it != levels_.end()) return *it->second.evaluator;
    Level& l = levels_[proxyLevel];
    l.proxies = makeProxies(points_, proxyLevel);
    l.tree = std::make_unique<PointIndex>(l.proxies.position);
    l.evaluator =
        std::make_unique<SdfEvaluator>(l.proxies, *l.tree, options_.smoothing, options_.fit);
    return *l.evaluator;
  }

 private:
  struct Level {
    PointSet proxies;
    std::unique_ptr<PointIndex> tree;
    std::unique_ptr<SdfEvaluator> evaluator;
  };
  const PointSet& points_;
  const BuildOptions& options_;
  std::map<int, Level> levels_;
};

}  // namespace

Key128 lodKey(uint8_t level, const GridPoint& p) {
  return {p.x | uint64_t(p.y) << 32, p.z | uint64_t(level) << 32};
}

uint32_t LodField::find(uint8_t level, const GridPoint& p) const {
  const uint32_t* found = index.find(lodKey(level, p));
  return found ? *found : kNoNode;
}

LodField sampleLodCorners(const Octree& tree, const PointSet& points, const BuildOptions& options) {
  LodField field;
  std::map<int, std::vector<std::pair<uint32_t, GridPoint>>> byLevel;  // entry, point
  for (const OctreeNode& node : tree.nodes) {
    if (node.kind != NodeKind::Internal) continue;
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(node.level, node.key, c);
      const auto [entry, inserted] =
          field.index.insert(lodKey(node.level, p), uint32_t(field.value.size()));
      if (!inserted) continue;
      field.value.emplace_back();
      byLevel[node.level].push_back({*entry, p});
    }
  }
  ProxyPyramid pyramid(points, options);
  const double unit = std::ldexp(1.0, -kMaxLevel);
  for (const auto& [level, corners] : byLevel) {
    const SdfEvaluator& sdf = pyramid.forNodeLevel(level);
    const float minSigma = kLodSigmaFraction * float(std::ldexp(1.0, -level));
    tbb::parallel_for(tbb::blocked_range<size_t>(0, corners.size(), 256),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t i = r.begin(); i < r.end(); ++i) {
                          const GridPoint& p = corners[i].second;
                          field.value[corners[i].first] = sdf.evaluate(
                              glm::dvec3(p.x * unit, p.y * unit, p.z * unit), minSigma);
                        }
                      });
  }
  return field;
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
