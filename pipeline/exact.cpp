// Chunk runs of the octree stages (specs/pipeline.md §15, "overlap and own"): the stages run on
// the points of a box around a chunk's own cell, and mark every node that may come out
// differently from the run on all points. The marks start where a node's points or a query's
// points may reach past the box, and spread as far as balance rounds and closure passes of the
// run on all points could carry a difference; the own cell is accepted when none reaches it.
#include <algorithm>
#include <array>
#include <cmath>
#include <glm/vec3.hpp>

#include "stages.h"

namespace iso {
namespace {

constexpr double kRelativeSlack = 1e-5;  // room for float rounding of query radii (frame units)
constexpr double kAbsoluteSlack = 1e-6;

struct CellBox {  // the closed box [lo, hi] of whole cells at `level`, in that level's cell units
  uint8_t level;
  std::array<int64_t, 3> lo, hi;
};

CellBox cellBox(uint8_t level, uint64_t key) {
  const auto c = mortonDecode(key);
  const std::array<int64_t, 3> lo = {int64_t(c[0]), int64_t(c[1]), int64_t(c[2])};
  return {level, lo, {lo[0] + 1, lo[1] + 1, lo[2] + 1}};
}

// Whether the node's (closed) cell meets the (closed) box.
bool meets(const OctreeNode& node, const CellBox& box) {
  const auto c = mortonDecode(node.key);
  for (int a = 0; a < 3; ++a) {
    // Compare at the finer of the two levels.
    const int64_t begin = int64_t(c[size_t(a)]), end = begin + 1;
    if (node.level >= box.level) {
      const int shift = node.level - box.level;
      if (end < (box.lo[size_t(a)] << shift) || begin > (box.hi[size_t(a)] << shift)) return false;
    } else {
      const int shift = box.level - node.level;
      if ((end << shift) < box.lo[size_t(a)] || (begin << shift) > box.hi[size_t(a)]) return false;
    }
  }
  return true;
}

// Visit the nodes of the subtree at `node` that meet the box, depth first; visit returns false to
// stop (then so does this).
template <typename Visit>
bool visitMeeting(const Octree& tree, uint32_t node, const CellBox& box, const Visit& visit) {
  const OctreeNode& n = tree.nodes[node];
  if (!meets(n, box)) return true;
  if (!visit(node)) return false;
  if (n.kind != NodeKind::Internal) return true;
  for (uint32_t c = 0; c < 8; ++c)
    if (!visitMeeting(tree, n.firstChild + c, box, visit)) return false;
  return true;
}

// The keys of the 27 cells of a level around a cell (itself included), inside the cube.
std::vector<uint64_t> cellsAround(uint8_t level, uint64_t key) {
  const auto c = mortonDecode(key);
  const int64_t cells = int64_t{1} << level;
  std::vector<uint64_t> out;
  for (int d = 0; d < 27; ++d) {
    const std::array<int64_t, 3> n = {int64_t(c[0]) + d % 3 - 1, int64_t(c[1]) + (d / 3) % 3 - 1,
                                      int64_t(c[2]) + d / 9 - 1};
    if (n[0] >= 0 && n[1] >= 0 && n[2] >= 0 && n[0] < cells && n[1] < cells && n[2] < cells)
      out.push_back(mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])));
  }
  return out;
}

// The cell itself and the cells of its level across its 6 faces, inside the cube.
std::vector<uint64_t> faceNeighbors(uint8_t level, uint64_t key) {
  const auto c = mortonDecode(key);
  const int64_t cells = int64_t{1} << level;
  std::vector<uint64_t> out = {key};
  for (int face = 0; face < 6; ++face) {
    std::array<int64_t, 3> n = {int64_t(c[0]), int64_t(c[1]), int64_t(c[2])};
    n[size_t(face / 2)] += face % 2 ? 1 : -1;
    if (n[size_t(face / 2)] >= 0 && n[size_t(face / 2)] < cells)
      out.push_back(mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])));
  }
  return out;
}

// Visit every node that meets the closed cell (level, key) from outside or inside: the nodes on
// the paths to the 27 cells around it and the subtrees at that level that meet it. A node may
// be visited more than once.
template <typename Visit>
bool visitAround(const Octree& tree, uint8_t level, uint64_t key, const Visit& visit) {
  const CellBox box = cellBox(level, key);
  for (uint64_t around : cellsAround(level, key)) {
    const uint32_t node = tree.find(level, around);
    if (tree.nodes[node].level < level) {
      if (!visit(node)) return false;
    } else if (!visitMeeting(tree, node, box, visit)) {
      return false;
    }
  }
  return true;
}

// The roots of the inexact subtrees (inexact nodes under exact ones; below them all inherit it).
std::vector<uint32_t> inexactRoots(const Octree& tree) {
  std::vector<uint32_t> roots, stack = {0};
  while (!stack.empty()) {
    const uint32_t id = stack.back();
    stack.pop_back();
    if (!tree.isExact(id)) {
      roots.push_back(id);
      continue;
    }
    const OctreeNode& n = tree.nodes[id];
    if (n.kind == NodeKind::Internal)
      for (uint32_t c = 0; c < 8; ++c) stack.push_back(n.firstChild + c);
  }
  return roots;
}

// Mark the exact nodes around inexact ones for which `qualifies` holds; returns whether any was.
template <typename Qualifies>
bool markAroundInexact(Octree& tree, const Qualifies& qualifies) {
  std::vector<uint32_t> marked;
  for (uint32_t root : inexactRoots(tree)) {
    const OctreeNode& r = tree.nodes[root];
    visitAround(tree, r.level, r.key, [&](uint32_t id) {
      if (tree.isExact(id) && qualifies(tree.nodes[id])) marked.push_back(id);
      return true;
    });
  }
  for (uint32_t id : marked) tree.markInexact(id);  // one step at a time: marked ones wait
  return !marked.empty();
}

}  // namespace

bool LoadedBox::holdsBall(const glm::dvec3& center, double radius) const {
  const double r = radius * (1.0 + kRelativeSlack) + kAbsoluteSlack;
  for (int a = 0; a < 3; ++a)
    if (!(center[a] - r >= lo[a] && center[a] + r <= hi[a])) return false;
  return true;
}

bool LoadedBox::holdsCell(uint8_t level, uint64_t key, double margin) const {
  const auto c = mortonDecode(key);
  const double size = std::ldexp(1.0, -level);
  for (int a = 0; a < 3; ++a) {
    const double begin = double(c[size_t(a)]) * size;
    if (!(begin - margin >= lo[a] && begin + size + margin <= hi[a])) return false;
  }
  return true;
}

bool LoadedBox::meetsCell(uint8_t level, uint64_t key) const {
  const auto c = mortonDecode(key);
  const double size = std::ldexp(1.0, -level);
  for (int a = 0; a < 3; ++a) {
    const double begin = double(c[size_t(a)]) * size;
    if (begin > hi[a] || begin + size < lo[a]) return false;
  }
  return true;
}

bool touchesInexact(const Octree& tree, uint8_t level, uint64_t key) {
  return !visitAround(tree, level, key, [&](uint32_t id) { return tree.isExact(id); });
}

bool spreadBalanceRound(Octree& tree, int round) {
  const int bound = int(tree.box->maxLeafLevel) - round - 1;
  if (bound < 1) return false;
  return markAroundInexact(tree,
                           [&](const OctreeNode& n) { return n.isFilled() && n.level <= bound; });
}

void spreadRemainingBalanceRounds(Octree& tree, int round) {
  // A round that marks nothing ends it: later rounds ask for coarser leaves only.
  while (spreadBalanceRound(tree, round)) ++round;
}

namespace {

// Whether the closure of a run on all points may fill part of the cell: its exits cross a face
// within the radius of influence of the nearest point, so some point's radius must reach the cell
// (a loaded one, or one beyond the box).
bool mayBeFilled(const Octree& tree, const PointSet& points, uint8_t level, uint64_t key) {
  if (!tree.box->holdsCell(level, key, tree.box->maxRadius)) return true;
  const auto c = mortonDecode(key);
  const double size = std::ldexp(1.0, -level);
  const glm::dvec3 lo = glm::dvec3(c[0], c[1], c[2]) * size;
  return tree.anyPointNear(lo, lo + size, points, [](uint32_t) { return true; });
}

}  // namespace

void spreadClosurePass(Octree& tree, const PointSet& points) {
  // A leaf inside an inexact node X fills cells of its own level across its faces: they lie in X
  // or in the cells of X's level across X's faces. Empty nodes there are marked; a larger empty
  // node is split down to them first (empty nodes split or not are the same to every stage), so
  // that what is marked stays near X. Only cells some point's radius reaches can be filled.
  std::vector<uint32_t> marked;
  std::vector<std::pair<uint8_t, uint64_t>> split;
  for (uint32_t root : inexactRoots(tree)) {
    const OctreeNode& x = tree.nodes[root];
    const CellBox box = cellBox(x.level, x.key);
    for (uint64_t around : faceNeighbors(x.level, x.key)) {
      const uint32_t node = tree.find(x.level, around);
      const OctreeNode& n = tree.nodes[node];
      if (n.level < x.level) {
        if (tree.isExact(node) && n.kind == NodeKind::Empty &&
            mayBeFilled(tree, points, x.level, around))
          split.push_back({x.level, around});
        continue;
      }
      visitMeeting(tree, node, box, [&](uint32_t id) {
        const OctreeNode& e = tree.nodes[id];
        if (tree.isExact(id) && e.kind == NodeKind::Empty &&
            mayBeFilled(tree, points, e.level, e.key))
          marked.push_back(id);
        return true;
      });
    }
  }
  std::sort(split.begin(), split.end());
  for (const auto& [level, key] : split) {
    const uint32_t node = tree.materialize(level, key, points);
    if (tree.nodes[node].kind == NodeKind::Empty) marked.push_back(node);
  }
  for (uint32_t id : marked) tree.markInexact(id);
}

void addCoarseCells(CoarseCells& cells, const PointSet& points, size_t begin, size_t end) {
  for (size_t i = begin; i < end; ++i) {
    const uint64_t key = points.key[i];
    for (uint8_t level = 1; level <= kCoarseLevel; ++level) {
      const uint64_t cell = key >> (3 * (kMaxLevel - level));
      ++*cells.points.insert(CoarseCells::cellCode(level, cell), 0).first;
      // The cells of this level other than the point's own that its disk's box reaches.
      const glm::dvec3 p(points.position[i]);
      const double r = points.radius[i], size = std::ldexp(1.0, -level);
      const auto own = mortonDecode(cell);
      std::array<int64_t, 3> lo{}, hi{};
      for (int a = 0; a < 3; ++a) {
        lo[size_t(a)] = std::max<int64_t>(0, int64_t(std::floor((p[a] - r) / size)));
        hi[size_t(a)] = std::min<int64_t>((int64_t{1} << level) - 1,
                                          int64_t(std::floor((p[a] + r) / size)));
      }
      for (int64_t z = lo[2]; z <= hi[2]; ++z)
        for (int64_t y = lo[1]; y <= hi[1]; ++y)
          for (int64_t x = lo[0]; x <= hi[0]; ++x) {
            if (x == own[0] && y == own[1] && z == own[2]) continue;
            const glm::dvec3 cellLo = glm::dvec3(x, y, z) * size;
            if (diskTouchesBox(points, uint32_t(i), cellLo, cellLo + size))
              cells.touched.insert(
                  CoarseCells::cellCode(level, mortonEncode(uint32_t(x), uint32_t(y), uint32_t(z))),
                  1);
          }
    }
  }
}

bool ownCellIsExact(const Octree& tree, const Closure& closure) {
  const LoadedBox& box = *tree.box;
  if (touchesInexact(tree, box.ownLevel, box.ownKey)) return false;
  const CornerField& field = closure.corners;
  std::vector<uint32_t> hangingAt(field.size(), kNoNode);  // corner → its hanging relation
  for (uint32_t h = 0; h < closure.hanging.size(); ++h) hangingAt[closure.hanging[h].corner] = h;
  // The corners the own cell's filled leaves use, and the sources they hang from, recursively.
  std::vector<uint8_t> seen(field.size(), 0);
  std::vector<uint32_t> work;
  const uint32_t own = tree.find(box.ownLevel, box.ownKey);
  visitMeeting(tree, own, cellBox(box.ownLevel, box.ownKey), [&](uint32_t id) {
    const OctreeNode& n = tree.nodes[id];
    if (n.isFilled())
      for (int c = 0; c < kCorners; ++c) {
        const uint32_t entry = field.find(cornerPoint(n.level, n.key, c));
        if (!seen[entry]) work.push_back(entry);
        seen[entry] = 1;
      }
    return true;
  });
  const uint32_t cells = 1u << kMaxLevel;
  while (!work.empty()) {
    const uint32_t entry = work.back();
    work.pop_back();
    if (!field.inexact.empty() && field.inexact[entry]) return false;
    // Its level and hanging relation come from the leaves around it.
    const GridPoint p = field.point(entry);
    for (int o = 0; o < 8; ++o) {
      const std::array<int64_t, 3> c = {int64_t(p.x) - (o & 1), int64_t(p.y) - ((o >> 1) & 1),
                                        int64_t(p.z) - ((o >> 2) & 1)};
      if (std::any_of(c.begin(), c.end(), [&](int64_t v) { return v < 0 || v >= cells; }))
        continue;
      const uint32_t node =
          tree.find(kMaxLevel, mortonEncode(uint32_t(c[0]), uint32_t(c[1]), uint32_t(c[2])));
      if (!tree.isExact(node)) return false;
    }
    if (hangingAt[entry] == kNoNode) continue;
    const HangingCorner& h = closure.hanging[hangingAt[entry]];
    for (int s = 0; s < h.sourceCount; ++s) {
      const uint32_t source = h.sources[size_t(s)];
      if (!seen[source]) work.push_back(source);
      seen[source] = 1;
    }
  }
  return true;
}

}  // namespace iso
