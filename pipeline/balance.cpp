// 2:1 balance (specs/pipeline.md, "Balance"): filled leaves that touch (across a face, an edge or
// a corner) differ by at most one level, so that every hanging corner lies on a face or an edge of
// a leaf exactly one level coarser, where snapping makes the patches agree.
#include <array>

#include "stages.h"

namespace iso {
namespace {

// Split a filled leaf without losing filled space: children are filled when they hold points or a
// disk touches them; a passive leaf filled to close the surface may have no disk touching any of
// its children, and then all of them stay filled.
void splitFilled(Octree& tree, const PointSet& points, uint32_t node, std::vector<uint32_t>& work,
                 std::vector<uint32_t>* created) {
  const bool wasPassive = tree.nodes[node].kind == NodeKind::Passive;
  tree.split(node, points);
  const uint32_t first = tree.nodes[node].firstChild;
  bool anyFilled = false;
  for (uint32_t c = 0; c < 8; ++c) {
    OctreeNode& child = tree.nodes[first + c];
    if (child.kind == NodeKind::Empty && isCoveredByDisk(tree, points, first + c)) child.kind = NodeKind::Passive;
    anyFilled = anyFilled || tree.nodes[first + c].isFilled();
  }
  for (uint32_t c = 0; c < 8; ++c) {
    if (wasPassive && !anyFilled) tree.nodes[first + c].kind = NodeKind::Passive;
    if (!tree.nodes[first + c].isFilled()) continue;
    work.push_back(first + c);
    if (created) created->push_back(first + c);
  }
}

// Balance the leaves on the work list (and those their splits create).
size_t balanceWork(Octree& tree, const PointSet& points, std::vector<uint32_t>& work, std::vector<uint32_t>* created) {
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
      const std::array<int64_t, 3> n = {int64_t(cell[0]) + d % 3 - 1, int64_t(cell[1]) + (d / 3) % 3 - 1,
                                        int64_t(cell[2]) + d / 9 - 1};
      if (n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= cells || n[1] >= cells || n[2] >= cells) continue;
      const uint64_t key = mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2]));
      for (;;) {
        const uint32_t neighbor = tree.find(level, key);
        const OctreeNode& other = tree.nodes[neighbor];
        if (!other.isFilled() || other.level + 1 >= level) break;
        splitFilled(tree, points, neighbor, work, created);
        ++splits;
      }
    }
  }
  return splits;
}

// The filled leaves inside an internal node that touch the box [lo, hi] (grid units of `level`).
void touchingLeaves(const Octree& tree, uint32_t node, const std::array<int64_t, 3>& lo,
                    const std::array<int64_t, 3>& hi, uint8_t level, std::vector<uint32_t>& out) {
  const OctreeNode& n = tree.nodes[node];
  const auto cell = mortonDecode(n.key);
  const int shift = n.level - level;  // finer cells: coordinates scale by 2^shift
  for (int a = 0; a < 3; ++a) {
    const int64_t begin = int64_t(cell[size_t(a)]), end = begin + 1;
    if (end < (lo[size_t(a)] << shift) || begin > (hi[size_t(a)] << shift)) return;
  }
  if (n.isFilled()) out.push_back(node);
  if (n.kind != NodeKind::Internal) return;
  for (uint32_t c = 0; c < 8; ++c) touchingLeaves(tree, n.firstChild + c, lo, hi, level, out);
}

}  // namespace

size_t balanceOctree(Octree& tree, const PointSet& points) {
  std::vector<uint32_t> work;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].isFilled()) work.push_back(i);
  return balanceWork(tree, points, work, nullptr);
}

size_t balanceAfter(Octree& tree, const PointSet& points, const std::vector<uint32_t>& added,
                    std::vector<uint32_t>& created) {
  // A new leaf may be too coarse for finer leaves next to it, which the work list must hold too.
  std::vector<uint32_t> work = added;
  for (uint32_t id : added) {
    const OctreeNode& leaf = tree.nodes[id];
    const auto c = mortonDecode(leaf.key);
    const std::array<int64_t, 3> lo = {int64_t(c[0]), int64_t(c[1]), int64_t(c[2])};  // the leaf's box
    const std::array<int64_t, 3> hi = {lo[0] + 1, lo[1] + 1, lo[2] + 1};
    for (int d = 0; d < 27; ++d) {
      const std::array<int64_t, 3> n = {lo[0] - 1 + d % 3, lo[1] - 1 + (d / 3) % 3, lo[2] - 1 + d / 9};
      if (d == 13 || n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= (int64_t{1} << leaf.level) ||
          n[1] >= (int64_t{1} << leaf.level) || n[2] >= (int64_t{1} << leaf.level))
        continue;
      const uint32_t node = tree.find(leaf.level, mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])));
      if (tree.nodes[node].kind == NodeKind::Internal && tree.nodes[node].level == leaf.level)
        touchingLeaves(tree, node, lo, hi, leaf.level, work);
    }
  }
  return balanceWork(tree, points, work, &created);
}

}  // namespace iso
