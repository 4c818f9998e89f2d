// 2:1 balance (specs/pipeline.md, "Balance"): filled leaves that touch (across a face, an edge or
// a corner) differ by at most one level, so that every hanging corner lies on a face or an edge of
// a leaf exactly one level coarser, where snapping makes the patches agree.
#include <array>

#include "stages.h"

namespace iso {
namespace {

// Split a filled leaf; its children are filled when they hold points or a disk touches them.
void splitFilled(Octree& tree, const PointSet& points, uint32_t node, std::vector<uint32_t>& work) {
  tree.split(node, points);
  const uint32_t first = tree.nodes[node].firstChild;
  for (uint32_t c = 0; c < 8; ++c) {
    OctreeNode& child = tree.nodes[first + c];
    if (child.kind == NodeKind::Empty && isCoveredByDisk(tree, points, first + c))
      child.kind = NodeKind::Passive;
    if (tree.nodes[first + c].isFilled()) work.push_back(first + c);
  }
}

}  // namespace

size_t balanceOctree(Octree& tree, const PointSet& points) {
  std::vector<uint32_t> work;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].isFilled()) work.push_back(i);
  size_t splits = 0;
  while (!work.empty()) {
    const uint32_t id = work.back();
    work.pop_back();
    if (!tree.nodes[id].isFilled()) continue;  // split since it was queued
    const uint8_t level = tree.nodes[id].level;
    const auto cell = mortonDecode(tree.nodes[id].key);
    const int64_t cells = int64_t{1} << level;
    for (int d = 0; d < 27; ++d) {
      if (d == 13) continue;  // the leaf itself
      const std::array<int64_t, 3> n = {int64_t(cell[0]) + d % 3 - 1,
                                        int64_t(cell[1]) + (d / 3) % 3 - 1,
                                        int64_t(cell[2]) + d / 9 - 1};
      if (n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= cells || n[1] >= cells || n[2] >= cells)
        continue;
      const uint64_t key = mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2]));
      for (;;) {
        const uint32_t neighbor = tree.find(level, key);
        const OctreeNode& other = tree.nodes[neighbor];
        if (!other.isFilled() || other.level + 1 >= level) break;
        splitFilled(tree, points, neighbor, work);
        ++splits;
      }
    }
  }
  return splits;
}

}  // namespace iso
