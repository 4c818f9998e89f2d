// Leaf corner sampling (specs/pipeline.md, "Corner sampling"): every distinct corner of the filled
// leaves is evaluated once, so corners shared by up to 8 leaves agree by construction; values
// already evaluated (while building the octree) come from the cache.
#include <tbb/parallel_for.h>

#include <cmath>

#include "progress.h"
#include "stages.h"

namespace iso {
Key128 gridKey(const GridPoint& p) { return {p.x | uint64_t(p.y) << 32, p.z}; }

uint32_t CornerField::find(const GridPoint& p) const {
  return index.find(gridKey(p));  // kNone is kNoNode
}

void addLeafCorners(CornerField& field, const Octree& tree, std::span<const uint32_t> leaves,
                    const SdfEvaluator& sdf, CornerCache& cache) {
  const size_t first = field.point.size();
  for (uint32_t id : leaves) {
    const OctreeNode& node = tree.nodes[id];
    if (!node.isFilled()) continue;
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(node.level, node.key, c);
      const auto [entry, inserted] = field.index.insert(gridKey(p));
      if (inserted) {
        field.point.push_back(p);
        field.coarsestLevel.push_back(node.level);
      } else {
        field.coarsestLevel[entry] = std::min(field.coarsestLevel[entry], node.level);
      }
    }
  }
  field.value.resize(field.point.size());
  const double unit = std::ldexp(1.0, -kMaxLevel);
  tbb::parallel_for(tbb::blocked_range<size_t>(first, field.point.size(), 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      progressAdvance(r.size());
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const GridPoint& p = field.point[i];
                        if (const CornerSample* known = cache.find(gridKey(p))) {
                          field.value[i] = *known;
                          continue;
                        }
                        field.value[i] = sdf.evaluate(glm::dvec3(p.x, p.y, p.z) * unit, 0.0f);
                      }
                    });
  for (size_t i = first; i < field.point.size(); ++i) cache.insert(gridKey(field.point[i]), field.value[i]);
}

CornerField sampleLeafCorners(const Octree& tree, const SdfEvaluator& sdf, CornerCache& cache) {
  CornerField field;
  std::vector<uint32_t> leaves;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].isFilled()) leaves.push_back(i);
  addLeafCorners(field, tree, leaves, sdf, cache);
  return field;
}

}  // namespace iso
