// Leaf corner sampling (specs/pipeline.md, "Corner sampling"): every distinct corner of the filled
// leaves is evaluated once, so corners shared by up to 8 leaves agree by construction. A corner's
// σ floor follows the coarsest leaf that uses it.
#include <tbb/parallel_for.h>

#include <cmath>

#include "stages.h"

namespace iso {
Key128 gridKey(const GridPoint& p) { return {p.x | uint64_t(p.y) << 32, p.z}; }

uint32_t CornerField::find(const GridPoint& p) const {
  const uint32_t* found = index.find(gridKey(p));
  return found ? *found : kNoNode;
}

CornerField sampleLeafCorners(const Octree& tree, const SdfEvaluator& sdf, CornerCache& cache) {
  CornerField field;
  for (const OctreeNode& node : tree.nodes) {
    if (!node.isFilled()) continue;
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(node.level, node.key, c);
      const auto [entry, inserted] = field.index.insert(gridKey(p), uint32_t(field.point.size()));
      if (inserted) {
        field.point.push_back(p);
        field.coarsestLevel.push_back(node.level);
      } else {
        field.coarsestLevel[*entry] = std::min(field.coarsestLevel[*entry], node.level);
      }
    }
  }
  field.value.resize(field.point.size());
  const double unit = std::ldexp(1.0, -kMaxLevel);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, field.point.size(), 256),
      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const GridPoint& p = field.point[i];
          if (const CornerSample* known = cache.find(lodKey(field.coarsestLevel[i], p))) {
            field.value[i] = *known;
            continue;
          }
          const glm::dvec3 q(p.x * unit, p.y * unit, p.z * unit);
          field.value[i] = sdf.evaluate(q, 0.0f);
        }
      });
  for (size_t i = 0; i < field.point.size(); ++i)  // for later passes (closeSurface)
    cache.insert(lodKey(field.coarsestLevel[i], field.point[i]), field.value[i]);
  return field;
}

}  // namespace iso
