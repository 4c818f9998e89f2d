// Leaf corner sampling (specs/pipeline.md, "Corner sampling"): every distinct corner of the filled
// leaves is evaluated once, so corners shared by up to 8 leaves agree by construction; values
// already evaluated (while building the octree) come from the cache.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "progress.h"
#include "stages.h"

namespace iso {
Key128 gridKey(const GridPoint& p) { return {p.x | uint64_t(p.y) << 32, p.z}; }

uint32_t CornerField::find(const GridPoint& p) const {
  return index.find(gridKey(p));  // kNone is kNoNode
}

GridPoint CornerField::point(uint32_t entry) const {
  const Key128& k = index.key(entry);
  return {uint32_t(k.a), uint32_t(k.a >> 32), uint32_t(k.b)};
}

void addLeafCorners(CornerField& field, const Octree& tree, std::span<const uint32_t> leaves,
                    const SdfEvaluator& sdf, CornerCache& cache) {
  const size_t first = field.size();
  for (uint32_t id : leaves) {
    const OctreeNode& node = tree.nodes[id];
    if (!node.isFilled()) continue;
    for (int c = 0; c < kCorners; ++c) {
      const GridPoint p = cornerPoint(node.level, node.key, c);
      const auto [entry, inserted] = field.index.insert(gridKey(p));
      if (inserted) {
        field.coarsestLevel.push_back(node.level);
      } else {
        field.coarsestLevel[entry] = std::min(field.coarsestLevel[entry], node.level);
      }
    }
  }
  field.value.resize(field.size());
  const bool chunk = tree.box != nullptr;
  if (chunk) field.inexact.resize(field.size(), 0);
  const double unit = std::ldexp(1.0, -kMaxLevel);
  tbb::parallel_for(tbb::blocked_range<size_t>(first, field.size(), 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      progressAdvance(r.size());
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const GridPoint p = field.point(uint32_t(i));
                        const Key128& key = field.index.key(uint32_t(i));
                        if (const CornerSample* known = cache.find(key)) {
                          field.value[i] = *known;
                          if (chunk) field.inexact[i] = !cache.isExact(key);
                          continue;
                        }
                        bool exact = true;
                        field.value[i] =
                            sdf.evaluate(glm::dvec3(p.x, p.y, p.z) * unit, 0.0f, &exact);
                        if (chunk) field.inexact[i] = !exact;
                      }
                    });
  for (size_t i = first; i < field.size(); ++i) {
    const Key128& key = field.index.key(uint32_t(i));
    if (cache.insert(key, field.value[i]).second && chunk && field.inexact[i])
      cache.markInexact(key);
  }
}

size_t refreshCornerLevels(CornerField& field, const Octree& tree) {
  std::fill(field.coarsestLevel.begin(), field.coarsestLevel.end(), kUnusedCorner);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, tree.nodes.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const OctreeNode& node = tree.nodes[i];
                        if (!node.isFilled()) continue;
                        for (int c = 0; c < kCorners; ++c) {
                          std::atomic_ref<uint8_t> level(
                              field.coarsestLevel[field.find(cornerPoint(node.level, node.key, c))]);
                          uint8_t seen = level.load(std::memory_order_relaxed);
                          while (node.level < seen && !level.compare_exchange_weak(seen, node.level))
                            ;
                        }
                      }
                    });
  return size_t(std::count_if(field.coarsestLevel.begin(), field.coarsestLevel.end(),
                              [](uint8_t l) { return l != kUnusedCorner; }));
}

CornerField sampleLeafCorners(const Octree& tree, const SdfEvaluator& sdf, CornerCache& cache) {
  CornerField field;
  std::vector<uint32_t> leaves;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].isFilled()) leaves.push_back(i);
  // About 2.25 distinct corners a leaf (neighbours share them): the arrays are reserved (address
  // space, not memory, where the estimate is high), not grown by copying.
  const size_t expected = leaves.size() * 5 / 2;
  field.index.reserveKeys(expected);
  field.coarsestLevel.reserve(expected);
  addLeafCorners(field, tree, leaves, sdf, cache);
  return field;
}

}  // namespace iso
