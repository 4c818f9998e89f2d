// Leaf corner sampling (specs/pipeline.md, "Corner sampling"): every distinct corner of the filled
// leaves is evaluated once, so corners shared by up to 8 leaves agree by construction; values
// already evaluated while building the octree are reused (one field holds both).
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "pipeline/base/buffers.h"
#include "pipeline/base/progress.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"

namespace iso {
Key128 gridKey(const GridPoint& p) { return {p.x | uint64_t(p.y) << 32, p.z}; }

uint32_t CornerField::find(const GridPoint& p) const {
  return index.find(gridKey(p));  // kNone is kNoNode
}

GridPoint CornerField::point(uint32_t entry) const {
  const Key128& k = index.key(entry);
  return {uint32_t(k.a), uint32_t(k.a >> 32), uint32_t(k.b)};
}

CornerField::CornerField(size_t expected, size_t reserved) : index(expected) {
  index.reserveKeys(reserved);
  coarsestLevel.reserve(reserved);
  value.reserve(reserved);
}

std::pair<uint32_t, bool> CornerField::insert(const Key128& key) {
  const auto [entry, added] = index.insert(key);
  if (added) {
    coarsestLevel.push_back(kUnusedCorner);
    value.emplace_back();
  }
  return {entry, added};
}

void addLeafCorners(CornerField& field, const Octree& tree, std::span<const uint32_t> leaves,
                    const SdfEvaluator& sdf) {
  SpillVector<uint32_t> added;  // entries to evaluate
  for (uint32_t id : leaves) {
    const OctreeNode& node = tree.nodes[id];
    if (!node.isFilled()) continue;
    for (int c = 0; c < kCorners; ++c) {
      const auto [entry, isNew] = field.insert(gridKey(cornerPoint(node.level, node.key, c)));
      if (isNew) added.push_back(entry);
      field.coarsestLevel[entry] = std::min(field.coarsestLevel[entry], node.level);
    }
  }
  evaluateCorners(field, added, sdf);
}

void evaluateCorners(CornerField& field, std::span<const uint32_t> entries,
                     const SdfEvaluator& sdf) {
  const double unit = std::ldexp(1.0, -kMaxLevel);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, entries.size(), 64),
                    [&](const tbb::blocked_range<size_t>& r) {
                      progressAdvance(r.size());
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const uint32_t entry = entries[i];
                        const GridPoint p = field.point(entry);
                        field.value[entry] = sdf.evaluate(glm::dvec3(p.x, p.y, p.z) * unit, 0.0f);
                      }
                    });
}

size_t refreshCornerLevels(CornerField& field, const Octree& tree) {
  std::fill(field.coarsestLevel.begin(), field.coarsestLevel.end(), kUnusedCorner);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, tree.nodes.size(), 4096),
      [&](const tbb::blocked_range<size_t>& r) {
        spillPause();
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

}  // namespace iso
