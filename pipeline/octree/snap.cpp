// Hanging corners (specs/pipeline.md, "Crack-free by construction"): a corner of a leaf that lies
// inside a face or an edge of a filled leaf one level coarser takes the bilinear (face) or linear
// (edge) interpolation of that leaf's corners there. Both trilinear patches then agree exactly on
// the shared face, so the zero set has no cracks. After 2:1 balance only a leaf exactly one level
// coarser can own such a face or edge.
#include <algorithm>
#include <glm/geometric.hpp>
#include <numeric>
#include <optional>
#include <span>
#include <vector>

#include "pipeline/base/collect.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"

namespace iso {
namespace {

// The hanging relation of one corner, if it has one.
std::optional<HangingCorner> hangingRelation(const Octree& tree, const CornerField& field,
                                             uint32_t corner) {
  const uint8_t level = field.coarsestLevel[corner];
  if (level == 0 || level == kUnusedCorner) return std::nullopt;
  const GridPoint p = field.point(corner);
  const uint32_t coarse = 1u << (kMaxLevel - level + 1);  // coarser cell size in grid units
  const std::array<uint32_t, 3> c = {p.x, p.y, p.z};
  std::array<bool, 3> onPlane{};
  int inside = 0;  // axes along which p is strictly inside a coarser cell
  for (int a = 0; a < 3; ++a) {
    onPlane[size_t(a)] = c[size_t(a)] % coarse == 0;
    inside += onPlane[size_t(a)] ? 0 : 1;
  }
  if (inside == 0 || inside == 3) return std::nullopt;  // a coarser grid point, or a cell centre
  // The coarser cells that have p on their boundary: on-plane axes give two choices each.
  for (int choice = 0; choice < 4; ++choice) {
    std::array<int64_t, 3> cell{};
    int bit = 0;
    for (int a = 0; a < 3; ++a) {
      cell[size_t(a)] = int64_t(c[size_t(a)] / coarse);
      if (onPlane[size_t(a)]) cell[size_t(a)] -= (choice >> bit++) & 1;
    }
    if (choice >> bit) break;  // all combinations tried
    const int64_t limit = int64_t{1} << (level - 1);
    if (std::any_of(cell.begin(), cell.end(), [&](int64_t v) { return v < 0 || v >= limit; }))
      continue;
    const uint64_t key = mortonEncode(uint32_t(cell[0]), uint32_t(cell[1]), uint32_t(cell[2]));
    const OctreeNode& node = tree.nodes[tree.find(uint8_t(level - 1), key)];
    if (!node.isFilled() || node.level != level - 1) continue;
    HangingCorner h{corner, {}, 0};
    for (int k = 0; k < kCorners; ++k) {  // the coarse leaf's corners on the same face or edge
      const GridPoint q = cornerPoint(node.level, node.key, k);
      const std::array<uint32_t, 3> qc = {q.x, q.y, q.z};
      bool same = true;
      for (int a = 0; a < 3; ++a)
        same = same && (!onPlane[size_t(a)] || qc[size_t(a)] == c[size_t(a)]);
      if (same) h.sources[h.sourceCount++] = field.find(q);
    }
    return h;
  }
  return std::nullopt;
}

// The coarsest level of the filled leaves that have p as a corner, or kUnusedCorner.
uint8_t coarsestLeafAt(const Octree& tree, const GridPoint& p) {
  std::array<uint32_t, 8> leaves{};
  const size_t count = filledLeavesAt(tree, p, leaves);
  uint8_t best = kUnusedCorner;
  for (size_t i = 0; i < count; ++i) best = std::min(best, tree.nodes[leaves[i]].level);
  return best;
}

}  // namespace

size_t filledLeavesAt(const Octree& tree, const GridPoint& p, std::array<uint32_t, 8>& out) {
  const std::array<uint32_t, 3> c = {p.x, p.y, p.z};
  constexpr uint32_t kCells = 1u << kMaxLevel;
  // Each such leaf holds one of the 8 finest cells around p, and the walk down the tree toward
  // each of them ends at the leaf that holds it. The walks share the path through the internal
  // nodes whose children hold p strictly inside.
  uint32_t start = 0;
  while (tree.nodes[start].kind == NodeKind::Internal) {
    const OctreeNode& node = tree.nodes[start];
    const int shift = kMaxLevel - node.level - 1;  // the children's size is 1 << shift
    const uint32_t inside = (1u << shift) - 1;
    if ((c[0] & inside) == 0 || (c[1] & inside) == 0 || (c[2] & inside) == 0) break;
    start = node.firstChild + uint32_t((mortonEncode(c[0], c[1], c[2]) >> (3 * shift)) & 7);
  }
  size_t count = 0;
  for (int d = 0; d < 8; ++d) {
    std::array<uint32_t, 3> x{};
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      const bool up = (d >> a) & 1;
      inside = inside && (up ? c[size_t(a)] < kCells : c[size_t(a)] > 0);
      x[size_t(a)] = up ? c[size_t(a)] : c[size_t(a)] - 1;
    }
    if (!inside) continue;
    const uint64_t finest = mortonEncode(x[0], x[1], x[2]);
    uint32_t id = start;
    while (tree.nodes[id].kind == NodeKind::Internal) {
      const OctreeNode& node = tree.nodes[id];
      id = node.firstChild + uint32_t((finest >> (3 * (kMaxLevel - node.level - 1))) & 7);
    }
    const OctreeNode& leaf = tree.nodes[id];
    const uint32_t size = 1u << (kMaxLevel - leaf.level);
    if (leaf.isFilled() && c[0] % size == 0 && c[1] % size == 0 && c[2] % size == 0 &&
        std::find(out.begin(), out.begin() + ptrdiff_t(count), id) ==
            out.begin() + ptrdiff_t(count))
      out[count++] = id;
  }
  return count;
}

void refreshCornersAround(const Octree& tree, Closure& closure, std::span<const uint32_t> changed,
                          std::span<const uint32_t> cornersOf) {
  CornerField& field = closure.corners;
  // What can change: the levels of a changed node's corners, and the relations of those and of
  // the corners that hung on it (corners of leaves one level finer, in the middles of its 12 edges
  // and 6 faces); for `cornersOf`, of their 8 corners.
  std::vector<uint32_t> touched;
  const auto touch = [&](uint32_t id, bool middles) {
    const OctreeNode& node = tree.nodes[id];
    const GridPoint o = cornerPoint(node.level, node.key, 0);
    const uint32_t size = 1u << (kMaxLevel - node.level);
    for (uint32_t i = 0; i < 27; ++i) {
      const std::array<uint32_t, 3> step = {i % 3, i / 3 % 3, i / 9};  // halves of the node
      const bool middle = step[0] == 1 || step[1] == 1 || step[2] == 1;
      if (i == 13 || (middle && (size == 1 || !middles))) continue;  // its centre; no finer leaf
      const uint32_t e = field.find(
          GridPoint{o.x + step[0] * size / 2, o.y + step[1] * size / 2, o.z + step[2] * size / 2});
      if (e != kNoNode) touched.push_back(e);
    }
  };
  for (const uint32_t id : changed) touch(id, true);
  for (const uint32_t id : cornersOf) touch(id, false);
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  for (const uint32_t e : touched) field.coarsestLevel[e] = coarsestLeafAt(tree, field.point(e));
  closure.cornersInUse =
      size_t(std::count_if(field.coarsestLevel.begin(), field.coarsestLevel.end(),
                           [](uint8_t l) { return l != kUnusedCorner; }));
  HangingCorners& hanging = closure.hanging;
  hanging.erase(std::remove_if(hanging.begin(), hanging.end(),
                               [&](const HangingCorner& h) {
                                 return std::binary_search(touched.begin(), touched.end(),
                                                           h.corner);
                               }),
                hanging.end());
  const auto kept = ptrdiff_t(hanging.size());
  for (const uint32_t e : touched)
    if (auto h = hangingRelation(tree, field, e)) hanging.push_back(*h);
  const auto before = [&](const HangingCorner& a, const HangingCorner& b) {
    return hangsBefore(field, a, b);
  };
  std::sort(hanging.begin() + kept, hanging.end(), before);
  std::inplace_merge(hanging.begin(), hanging.begin() + kept, hanging.end(), before);
  snapHangingCorners(field, hanging);
}

std::vector<uint8_t> filledNodes(const Octree& tree) {
  std::vector<uint8_t> filled(tree.nodes.size());
  for (size_t i = 0; i < filled.size(); ++i) filled[i] = tree.nodes[i].isFilled();
  return filled;
}

std::vector<uint32_t> nodesChangedSince(const Octree& tree, const std::vector<uint8_t>& filled) {
  std::vector<uint32_t> changed;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].isFilled() != (i < filled.size() && filled[i])) changed.push_back(i);
  return changed;
}

bool hangsBefore(const CornerField& field, const HangingCorner& a, const HangingCorner& b) {
  const uint8_t la = field.coarsestLevel[a.corner], lb = field.coarsestLevel[b.corner];
  return la != lb ? la < lb : a.corner < b.corner;
}

HangingCorners findHangingCorners(const Octree& tree, const CornerField& field) {
  HangingCorners hanging = collectInParallel<HangingCorner, HangingCorners>(
      field.size(), 1 << 14, [&](size_t i, std::vector<HangingCorner>& out) {
        if (auto h = hangingRelation(tree, field, uint32_t(i))) out.push_back(*h);
      });
  // Coarse first: a source may itself hang from a leaf another level up.
  std::stable_sort(hanging.begin(), hanging.end(),
                   [&](const HangingCorner& a, const HangingCorner& b) {
                     return field.coarsestLevel[a.corner] < field.coarsestLevel[b.corner];
                   });
  return hanging;
}

void snapHangingCorners(CornerField& field, const HangingCorners& hanging) {
  for (const HangingCorner& h : hanging) {
    CornerSample sum;
    sum.distance = 0.0f;
    sum.normal = glm::vec3(0.0f);
    for (int s = 0; s < h.sourceCount; ++s) {
      const CornerSample& v = field.value[h.sources[size_t(s)]];
      sum.distance += v.distance;
      sum.normal += v.normal;
      sum.color += v.color;
    }
    const float inv = 1.0f / float(h.sourceCount);
    CornerSample& out = field.value[h.corner];
    out.distance = sum.distance * inv;
    const float length = glm::length(sum.normal);
    out.normal = length > 0.0f ? sum.normal / length : out.normal;
    out.color = sum.color * inv;
  }
}

}  // namespace iso
