// 2:1 balance (specs/pipeline.md, "Balance"): filled leaves that touch (across a face, an edge or
// a corner) differ by at most one level, so that every hanging corner lies on a face or an edge of
// a leaf exactly one level coarser, where snapping makes the patches agree.
//
// Balance runs in rounds. A round reads the tree as it stands: every filled leaf on the work list
// asks for the filled leaves more than one level coarser next to it to be split down to one level
// above its own; then all the asked splits are made, in key order, and the filled leaves they
// create are the next round's work. So the result does not depend on the order in which leaves are
// visited (each round depends only on the one before, leaf by leaf on its 3×3×3 neighbourhood),
// the look-ups of a round run in parallel, and the node numbering is the same on every run.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>

#include "pipeline/base/buffers.h"
#include "pipeline/base/collect.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

// Split filled nodes on the path to the cell (level, key) until it is reached or the path ends in a
// node that is not filled.
struct Request {
  uint8_t level;
  uint64_t key;
  auto operator<=>(const Request&) const = default;
};

// The requests of one filled leaf: the cells one level above it next to it whose path ends in a
// filled leaf coarser than that.
void requestsOf(const Octree& tree, uint32_t id, std::vector<Request>& out) {
  const OctreeNode& leaf = tree.nodes[id];
  if (!leaf.isFilled() || leaf.level < 2) return;
  const uint8_t level = leaf.level;
  const auto cell = mortonDecode(leaf.key);
  const int64_t cells = int64_t{1} << level;
  for (int d = 0; d < 27; ++d) {
    if (d == 13) continue;  // the leaf itself
    const std::array<int64_t, 3> n = {int64_t(cell[0]) + d % 3 - 1,
                                      int64_t(cell[1]) + (d / 3) % 3 - 1,
                                      int64_t(cell[2]) + d / 9 - 1};
    if (n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= cells || n[1] >= cells || n[2] >= cells)
      continue;
    const uint64_t key = mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2]));
    const OctreeNode& other = tree.nodes[tree.find(level, key)];
    if (other.isFilled() && other.level + 1 < level) out.push_back({uint8_t(level - 1), key >> 3});
  }
}

// Sorted requests without repeats.
void unique(std::vector<Request>& sorted) {
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
}

// The requests of all leaves on the work list, sorted and without repeats (in parallel). Neighbours
// ask for the same cells many times over: the requests are made and thinned out a million leaves
// at a time, so that the repeats never pile up (the result is the same).
std::vector<Request> requestsOf(const Octree& tree, const std::vector<uint32_t>& work) {
  constexpr size_t kBatch = size_t{1} << 20;
  std::vector<Request> all;
  for (size_t begin = 0; begin < work.size(); begin += kBatch) {
    const size_t count = std::min(kBatch, work.size() - begin);
    std::vector<Request> batch = collectInParallel<Request>(
        count, 4096,
        [&](size_t i, std::vector<Request>& out) { requestsOf(tree, work[begin + i], out); });
    std::sort(batch.begin(), batch.end());
    unique(batch);
    std::vector<Request> merged(all.size() + batch.size());
    merged.erase(std::merge(all.begin(), all.end(), batch.begin(), batch.end(), merged.begin()),
                 merged.end());
    all.swap(merged);
    unique(all);
  }
  return all;
}

// Split the filled nodes (in the given order) without losing filled space: children are filled
// when they hold points or a disk touches them; a passive node none of whose children a disk
// touches keeps all of them filled. The filled children are appended to `created`.
void splitFilled(Octree& tree, const PointSet& points, const std::vector<uint32_t>& nodes,
                 std::vector<uint32_t>& created) {
  std::vector<uint32_t> empty;  // children without points, to test against the disks
  std::vector<uint8_t> wasPassive(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    const uint32_t id = nodes[i];
    wasPassive[i] = tree.nodes[id].kind == NodeKind::Passive;
    tree.split(id, points);
    const uint32_t first = tree.nodes[id].firstChild;
    for (uint32_t c = 0; c < 8; ++c)
      if (tree.nodes[first + c].kind == NodeKind::Empty) empty.push_back(first + c);
  }
  std::vector<uint8_t> covered(empty.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, empty.size(), 16),
                    [&](const tbb::blocked_range<size_t>& r) {
                      spillPause();
                      for (size_t i = r.begin(); i < r.end(); ++i)
                        covered[i] = isCoveredByDisk(tree, points, empty[i]);
                    });
  for (size_t i = 0; i < empty.size(); ++i)
    if (covered[i]) tree.nodes[empty[i]].kind = NodeKind::Passive;
  for (size_t i = 0; i < nodes.size(); ++i) {
    const uint32_t first = tree.nodes[nodes[i]].firstChild;
    bool anyFilled = false;
    for (uint32_t c = 0; c < 8; ++c) anyFilled = anyFilled || tree.nodes[first + c].isFilled();
    for (uint32_t c = 0; c < 8; ++c) {
      if (wasPassive[i] && !anyFilled) tree.nodes[first + c].kind = NodeKind::Passive;
      if (tree.nodes[first + c].isFilled()) created.push_back(first + c);
    }
  }
}

// Balance the leaves on the work list and those their splits create, round by round.
size_t balanceRounds(Octree& tree, const PointSet& points, std::vector<uint32_t> work,
                     std::vector<uint32_t>* createdOut) {
  size_t splits = 0;
  while (!work.empty()) {
    const std::vector<Request> requests = requestsOf(tree, work);
    std::vector<uint32_t> created;
    // Walk down the requested paths one level at a time: the filled nodes at the ends of the
    // paths are split together (in key order), then the paths are followed again.
    for (;;) {
      std::vector<uint32_t> nodes;
      for (const Request& r : requests) {
        const uint32_t node = tree.find(r.level, r.key);
        if (tree.nodes[node].isFilled() && tree.nodes[node].level < r.level) nodes.push_back(node);
      }
      if (nodes.empty()) break;
      const auto byCell = [&](uint32_t a, uint32_t b) {
        const OctreeNode &x = tree.nodes[a], &y = tree.nodes[b];
        return x.level != y.level ? x.level < y.level : x.key < y.key;
      };
      std::sort(nodes.begin(), nodes.end(), byCell);
      nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
      splitFilled(tree, points, nodes, created);
      splits += nodes.size();
    }
    work.clear();
    for (uint32_t id : created)
      if (tree.nodes[id].isFilled()) work.push_back(id);  // not split again in this round
    if (createdOut) createdOut->insert(createdOut->end(), work.begin(), work.end());
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
  return balanceRounds(tree, points, std::move(work), nullptr);
}

size_t balanceAfter(Octree& tree, const PointSet& points, const std::vector<uint32_t>& added,
                    std::vector<uint32_t>& created) {
  // A new leaf may be too coarse for finer leaves next to it, which the work list must hold too.
  std::vector<uint32_t> work = added;
  for (uint32_t id : added) {
    const OctreeNode& leaf = tree.nodes[id];
    const auto c = mortonDecode(leaf.key);
    const std::array<int64_t, 3> lo = {int64_t(c[0]), int64_t(c[1]), int64_t(c[2])};  // its box
    const std::array<int64_t, 3> hi = {lo[0] + 1, lo[1] + 1, lo[2] + 1};
    const int64_t cells = int64_t{1} << leaf.level;
    for (int d = 0; d < 27; ++d) {
      const std::array<int64_t, 3> n = {lo[0] - 1 + d % 3, lo[1] - 1 + (d / 3) % 3,
                                        lo[2] - 1 + d / 9};
      if (d == 13 || n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= cells || n[1] >= cells ||
          n[2] >= cells)
        continue;
      const uint32_t node =
          tree.find(leaf.level, mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])));
      if (tree.nodes[node].kind == NodeKind::Internal && tree.nodes[node].level == leaf.level)
        touchingLeaves(tree, node, lo, hi, leaf.level, work);
    }
  }
  std::sort(work.begin(), work.end());
  work.erase(std::unique(work.begin(), work.end()), work.end());
  return balanceRounds(tree, points, std::move(work), &created);
}

}  // namespace iso
