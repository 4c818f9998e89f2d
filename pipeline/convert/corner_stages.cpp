// The octree stages before the level of detail, in one run or as chunk jobs (specs/pipeline.md §15,
// "Chunk runs of the octree stages").
//
// Why a chunk job reads a bounded neighbourhood: a node wider than maxTestedEdge spacings, or
// holding more than maxTestedPoints points, is subdivided without a test, so every node whose
// decision reads points, and every leaf with points, is at most a tested cell wide. A chunk's halo
// is the tested cells with points around its owned cells, loaded whole: the nodes next to the
// owned cells hold all their points, and the signed distance, coverage, disk and corner-fit reads
// of the owned nodes reach a few radii, inside the halo. Nodes cut by the halo's outer edge may
// decide otherwise than with all their points, and what follows from them (closure chains,
// balance cascades) starts a tested cell from the owned cells. Where two chunks still disagree at
// a seam, the merge balances the leaves and closes the surface across it. Whatever the halo
// holds, the result is a function of the points and the options: the plan depends on nothing else.
#include "pipeline/convert/corner_stages.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <thread>

#include "iso/check.h"
#include "pipeline/base/files.h"
#include "pipeline/base/progress.h"
#include "pipeline/points/knn.h"

namespace iso {

CornerStageResults runCornerStages(PointSet& points, const SdfEvaluator& sdf,
                                   const BuildOptions& options, const RadiusStats& radii,
                                   uint8_t minPassiveLevel,
                                   const std::function<void(const char*)>& stage) {
  stage("octree");
  CornerStageResults r;
  // One field for the corners the octree tests and those of the leaves: 0.40 a point on the 3M
  // dragon, 0.67 on the lion, 0.87 on the lone-star scan. The table is made and the arrays are
  // reserved for half a point (they double where there are more): out of core, reserved room is
  // temporary disk.
  CornerField cornerField(points.size() / 2, points.size() / 2);
  r.octree = buildOctree(points, sdf, options, radii, cornerField, &r.stats);
  Octree& octree = r.octree;
  stage("passive+balance");
  r.passive = markPassiveLeaves(octree, points, minPassiveLevel);
  r.splits = balanceOctree(octree, points);
  stage("corners");
  r.closure = sampleClosedSurface(octree, points, sdf, std::move(cornerField));
  Closure& closure = r.closure;
  {
    std::vector<uint8_t> wasNegative(closure.corners.size());
    for (size_t e = 0; e < wasNegative.size(); ++e)
      wasNegative[e] = closure.corners.value[e].distance < 0.0f;
    if (fitCornersToPoints(closure.corners, closure.hanging, octree, points, options.cornerFit) > 0)
      closeAgain(octree, points, sdf, closure, wasNegative);
  }
  r.trimmed =
      options.fillHoles ? 0 : trimFarSurface(octree, points, sdf, closure, options.trimReach);
  octree.nodes.shrink_to_fit();  // no more splits: the room grown for them is not needed
  return r;
}

namespace {

using Clock = std::chrono::steady_clock;

int shiftOf(uint8_t level) { return 3 * (kMaxLevel - level); }

// Calls f(cellKey, begin, end) for every cell of `level` that holds points, in key order.
template <typename F>
void forEachCell(const PointSet& points, uint8_t level, F&& f) {
  const int shift = shiftOf(level);
  const auto keys = points.key.begin();
  size_t i = 0;
  while (i < points.size()) {
    const uint64_t cell = keys[ptrdiff_t(i)] >> shift;
    const size_t end =
        size_t(std::partition_point(keys + ptrdiff_t(i), points.key.end(),
                                    [&](uint64_t k) { return (k >> shift) <= cell; }) -
               keys);
    f(cell, uint32_t(i), uint32_t(end));
    i = end;
  }
}

// Calls f(neighbourKey) for the cells of `level` next to the cell `key` (across a face, an edge or
// a corner) inside the frame.
template <typename F>
void forEachNeighbour(uint8_t level, uint64_t key, F&& f) {
  const auto c = mortonDecode(key);
  const int64_t cells = int64_t{1} << level;
  for (int d = 0; d < 27; ++d) {
    const std::array<int64_t, 3> n = {int64_t(c[0]) + d % 3 - 1, int64_t(c[1]) + (d / 3) % 3 - 1,
                                      int64_t(c[2]) + d / 9 - 1};
    if (d == 13 || n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= cells || n[1] >= cells ||
        n[2] >= cells)
      continue;
    f(mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])));
  }
}

// The chunk owning a cell of the plan's level.
size_t ownerOf(const OctreeChunkPlan& plan, uint64_t cell) {
  return size_t(std::upper_bound(plan.firstCell.begin(), plan.firstCell.end(), cell) -
                plan.firstCell.begin()) -
         1;
}

using PointRange = std::pair<uint32_t, uint32_t>;

// The halo of every chunk: its ranges of points in key order.
std::vector<std::vector<PointRange>> haloRanges(const PointSet& points,
                                                const OctreeChunkPlan& plan) {
  std::vector<std::vector<PointRange>> halos(plan.chunks());
  const int up = 3 * (plan.haloLevel - plan.cellLevel);
  forEachCell(points, plan.haloLevel, [&](uint64_t cell, uint32_t begin, uint32_t end) {
    const size_t own = ownerOf(plan, cell >> up);
    std::array<size_t, 26> touched{};
    size_t count = 0;
    forEachNeighbour(plan.haloLevel, cell, [&](uint64_t neighbour) {
      const size_t chunk = ownerOf(plan, neighbour >> up);
      const auto seen = touched.begin() + ptrdiff_t(count);
      if (chunk != own && std::find(touched.begin(), seen, chunk) == seen) touched[count++] = chunk;
    });
    for (size_t k = 0; k < count; ++k) halos[touched[k]].push_back({begin, end});
  });
  return halos;
}

// The points of the ranges (sorted, disjoint), in key order.
PointSet gather(const PointSet& points, const std::vector<PointRange>& ranges) {
  PointSet local;
  size_t n = 0;
  for (const PointRange& r : ranges) n += r.second - r.first;
  PointSet::forEachColumn(
      [&](auto& to, const auto& from) {
        if (from.empty()) return;
        to.reserve(n);
        for (const PointRange& r : ranges)
          to.insert(to.end(), from.begin() + r.first, from.begin() + r.second);
      },
      local, points);
  return local;
}

// Builds the merged tree and corner field from the chunks' owned parts.
class ChunkMerger {
 public:
  ChunkMerger(const PointSet& points, const OctreeChunkPlan& plan)
      : points_(points), plan_(plan), cellLevel_(plan.cellLevel), field_(1024, points.size() / 2) {
    // Each chunk's corners get their own stretch of the table (cell_index.h): the merge and the
    // stages after it find corners in Morton order.
    field_.index.cutByCells(plan.cut(), points.size() / 2);
    OctreeNode root;
    root.pointEnd = uint32_t(points.size());
    root.kind = NodeKind::Empty;
    tree_.nodes.push_back(root);
  }

  // Take the nodes of chunk `index` (run over local points whose owned ones start at ownLocal;
  // they start at ownGlobal in all points) below the cells [firstCell, endCell) of the plan's
  // level.
  void add(const CornerStageResults& chunk, size_t index, uint64_t firstCell, uint64_t endCell,
           uint32_t ownLocal, uint32_t ownGlobal) {
    std::vector<uint32_t> roots;
    ownedRoots(chunk.octree, 0, firstCell, endCell, roots);
    const int64_t offset = int64_t(ownGlobal) - int64_t(ownLocal);
    std::vector<std::pair<uint32_t, uint32_t>> filled;  // (merged node, chunk node)
    for (const uint32_t root : roots) {
      const OctreeNode& r = chunk.octree.nodes[root];
      copySubtree(chunk.octree, root, slotAt(r.key), offset, filled);
    }
    // The corners the owned filled leaves use, each taken once (a corner is shared by up to 8),
    // in the chunk field's order.
    const CornerField& corners = chunk.closure.corners;
    std::vector<uint8_t> used(corners.size(), 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, filled.size(), 4096),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t i = r.begin(); i < r.end(); ++i) {
                          const OctreeNode& leaf = chunk.octree.nodes[filled[i].second];
                          for (int c = 0; c < kCorners; ++c) {
                            const uint32_t e = corners.find(cornerPoint(leaf.level, leaf.key, c));
                            ISO_CHECK(e != kNoNode);  // a filled leaf's corners are in its field
                            std::atomic_ref<uint8_t>(used[e]).store(1, std::memory_order_relaxed);
                          }
                        }
                      });
    field_.index.openPart(index, size_t(std::count(used.begin(), used.end(), uint8_t{1})));
    // With the values, the chunk's corner levels and hanging corners: those of a corner no leaf of
    // another chunk uses, away from the seams, are what the merged tree gives (refreshed around
    // the seams in finish()).
    std::vector<uint32_t> merged(used.size(), kNoNode);
    std::vector<uint8_t> first(used.size(), 0);  // the first chunk using the corner
    for (uint32_t e = 0; e < used.size(); ++e) {
      if (!used[e]) continue;
      const auto [entry, added] = field_.insert(corners.index.key(e));
      merged[e] = entry;
      first[e] = added;
      if (!added) continue;
      field_.value[entry] = corners.value[e];
      field_.coarsestLevel[entry] = corners.coarsestLevel[e];
    }
    for (const HangingCorner& h : chunk.closure.hanging) {
      if (!first[h.corner]) continue;
      HangingCorner m = h;
      m.corner = merged[h.corner];
      bool known = true;
      for (size_t k = 0; k < h.sourceCount; ++k) {
        m.sources[k] = merged[h.sources[k]];
        known = known && m.sources[k] != kNoNode;
      }
      if (known) hanging_.push_back(m);
    }
    for (const auto& [merged, own] : filled)
      if (touchesOtherChunk(tree_.nodes[merged], index)) seamLeaves_.push_back(merged);
    lod_.insert(lod_.end(), chunk.lod.begin(), chunk.lod.end());
  }

  // The merged tree and field: cells above the plan's level with nothing filled below emptied,
  // seams balanced and closed (new leaves sampled with `sdf`), hanging corners found and snapped.
  CornerStageResults finish(const SdfEvaluator& sdf, const BuildOptions& options,
                            ChunkRunStats& stats) {
    for (size_t i = placeholders_.size(); i-- > 0;) {
      OctreeNode& node = tree_.nodes[placeholders_[i]];
      bool any = false;
      for (uint32_t c = 0; c < 8 && !any; ++c)
        any = tree_.nodes[node.firstChild + c].kind != NodeKind::Empty;
      if (!any) node.kind = NodeKind::Empty;
    }
    field_.index.closeParts();
    const std::vector<uint8_t> jobsFilled = filledNodes(tree_);
    std::vector<uint32_t> created;
    stats.seamSplits = balanceAfter(tree_, points_, seamLeaves_, created);
    CornerStageResults r;
    r.octree = std::move(tree_);
    std::sort(
        hanging_.begin(), hanging_.end(),
        [&](const HangingCorner& a, const HangingCorner& b) { return hangsBefore(field_, a, b); });
    r.closure.hanging = std::move(hanging_);
    r.closure.corners = std::move(field_);
    r.lod = std::move(lod_);
    // The surface closed across the seams (a job may not have filled a cell of another chunk's
    // that its own leaf's zero set runs into), from the seam leaves and the balance's new ones.
    std::vector<uint32_t> fresh;
    for (const uint32_t id : seamLeaves_)
      if (r.octree.nodes[id].isFilled()) fresh.push_back(id);
    fresh.insert(fresh.end(), created.begin(), created.end());
    const std::vector<uint8_t> wasFilled = filledNodes(r.octree);
    // Only exits into another chunk's cells: within its own cells, each job closed its surface.
    const auto ownerOfNode = [&](uint8_t level, uint64_t key) {
      return ownerOf(plan_, key >> (3 * (level - cellLevel_)));
    };
    closeFromLeaves(std::move(fresh), r.octree, points_, sdf, r.closure,
                    [&](uint8_t leafLevel, uint64_t leafKey, uint8_t level, uint64_t key) {
                      return ownerOfNode(leafLevel, leafKey) != ownerOfNode(level, key);
                    });
    // Levels and hanging corners found again where the seams changed the filled leaves (splits,
    // fills) and at the corners of the leaves next to another chunk's.
    refreshCornersAround(r.octree, r.closure, nodesChangedSince(r.octree, jobsFilled), seamLeaves_);
    // The jobs trimmed what their closures filled far from the points; so are the seams' fills.
    std::vector<uint32_t> filled;
    for (uint32_t i = 0; i < r.octree.nodes.size(); ++i)
      if (r.octree.nodes[i].isFilled() && (i >= wasFilled.size() || !wasFilled[i]))
        filled.push_back(i);
    const size_t trimmed = options.fillHoles ? 0
                                             : trimFarSurface(r.octree, points_, sdf, r.closure,
                                                              options.trimReach, &filled);
    stats.seamFills = filled.size() - trimmed;
    r.octree.nodes.shrink_to_fit();
    return r;
  }

 private:
  // The non-empty nodes of the plan's level in [firstCell, endCell), in key order.
  void ownedRoots(const Octree& tree, uint32_t id, uint64_t firstCell, uint64_t endCell,
                  std::vector<uint32_t>& out) const {
    const OctreeNode& node = tree.nodes[id];
    if (node.kind == NodeKind::Empty) return;
    const int down = 3 * (cellLevel_ - node.level);
    const uint64_t lo = node.key << down, hi = (node.key + 1) << down;
    if (hi <= firstCell || lo >= endCell) return;
    if (node.level == cellLevel_) {
      out.push_back(id);
      return;
    }
    // Leaves with points are never this coarse (nodes wider than the halo cells are split) and
    // passive leaves are not marked above the plan's level.
    ISO_CHECK(node.kind == NodeKind::Internal);
    for (uint32_t c = 0; c < 8; ++c) ownedRoots(tree, node.firstChild + c, firstCell, endCell, out);
  }

  // Whether a cell next to the leaf (same level, across a face, an edge or a corner) lies in a cell
  // of the plan's level that another chunk owns.
  bool touchesOtherChunk(const OctreeNode& leaf, size_t chunk) const {
    const int up = 3 * (leaf.level - cellLevel_);
    const auto c = mortonDecode(leaf.key);
    const uint32_t last = (1u << (leaf.level - cellLevel_)) - 1;
    if ((c[0] & last) != 0 && (c[0] & last) != last && (c[1] & last) != 0 &&
        (c[1] & last) != last && (c[2] & last) != 0 && (c[2] & last) != last)
      return false;  // inside its owned cell
    bool other = false;
    forEachNeighbour(leaf.level, leaf.key,
                     [&](uint64_t key) { other = other || ownerOf(plan_, key >> up) != chunk; });
    return other;
  }

  // The merged tree's node for the cell (cellLevel_, key), made a placeholder on first use.
  uint32_t slotAt(uint64_t key) {
    uint32_t id = 0;
    for (int l = 0; l < cellLevel_; ++l) {
      if (tree_.nodes[id].kind != NodeKind::Internal) {
        tree_.split(id, points_);
        placeholders_.push_back(id);
        const uint32_t first = tree_.nodes[id].firstChild;
        for (uint32_t c = 0; c < 8; ++c) tree_.nodes[first + c].kind = NodeKind::Empty;
      }
      id = tree_.nodes[id].firstChild + uint32_t((key >> (3 * (cellLevel_ - 1 - l))) & 7);
    }
    return id;
  }

  void copySubtree(const Octree& from, uint32_t root, uint32_t slot, int64_t offset,
                   std::vector<std::pair<uint32_t, uint32_t>>& filled) {
    std::vector<std::pair<uint32_t, uint32_t>> queue = {{root, slot}};
    for (size_t q = 0; q < queue.size(); ++q) {
      const auto [own, merged] = queue[q];
      OctreeNode node = from.nodes[own];
      node.pointBegin = uint32_t(int64_t(node.pointBegin) + offset);
      node.pointEnd = uint32_t(int64_t(node.pointEnd) + offset);
      if (node.kind == NodeKind::Internal) {
        const uint32_t first = uint32_t(tree_.nodes.size());
        tree_.nodes.resize(first + 8);
        for (uint32_t c = 0; c < 8; ++c) queue.push_back({node.firstChild + c, first + c});
        node.firstChild = first;
      } else {
        node.firstChild = kNoNode;
      }
      if (node.isFilled()) filled.push_back({merged, own});
      tree_.nodes[merged] = node;
    }
  }

  const PointSet& points_;
  const OctreeChunkPlan& plan_;
  uint8_t cellLevel_;
  Octree tree_;
  CornerField field_;
  std::vector<uint32_t> placeholders_;  // nodes above the plan's level, parents first
  std::vector<uint32_t> seamLeaves_;    // filled leaves next to another chunk's cells
  SpillVector<LodSample> lod_;          // the jobs' level-of-detail corners, in chunk order
  HangingCorners hanging_;              // the jobs' hanging corners, in merged entries
};

// What the ranks share: the points, and the chunk jobs' results, as checkpoints in a directory of
// rank 0's temporary directory.
constexpr const char* kShareFingerprint = "the octree stages' chunk jobs of one run";
constexpr const char* kSharedPoints = "points";

ResumeState sharedState(const Ranks& ranks) {
  return ResumeState(ranks.shared / "octree-chunks", kShareFingerprint);
}

// Chunk `c` for this rank: true for exactly one rank of the run. Ranks claim chunks in chunk
// order as they become free, so a rank that also merges (rank 0) takes fewer.
bool claimChunk(const ResumeState& share, size_t c) {
  return claimFile(share.path("claim-" + std::to_string(c)));
}

// The stages over the chunk's own points and its halo.
CornerStageResults runChunk(const PointSet& points, size_t chunk,
                            const std::vector<PointRange>& halo, const BuildOptions& options,
                            const RadiusStats& radii, const OctreeChunkPlan& plan,
                            const std::function<void(const char*)>& stage) {
  const PointRange own = {plan.firstPoint[chunk], plan.firstPoint[chunk + 1]};
  std::vector<PointRange> ranges;
  bool ownPlaced = false;
  for (const PointRange& r : halo) {
    if (!ownPlaced && r.first >= own.second) {
      ranges.push_back(own);
      ownPlaced = true;
    }
    ranges.push_back(r);
  }
  if (!ownPlaced) ranges.push_back(own);
  const ProgressMute mute;  // the job counts its own points when it ends
  PointSet local = gather(points, ranges);
  const auto index = std::make_unique<PointIndex>(local.position);
  const SdfEvaluator sdf(local, *index, options.smoothing, options.fit);
  CornerStageResults r = runCornerStages(local, sdf, options, radii, plan.cellLevel, stage);
  // The level of detail of the owned nodes finer than the halo's cells, where it reads only points
  // within a halo cell's width: the owned halo-level cell around such a corner and every cell next
  // to it are loaded whole, so the job evaluates what the whole run would.
  stage("lod");
  const uint64_t firstCell = plan.firstCell[chunk];
  const uint64_t endCell =
      chunk + 1 < plan.chunks() ? plan.firstCell[chunk + 1] : uint64_t{1} << (3 * plan.cellLevel);
  r.lod = sampleLodCornersWithin(
      r.octree, local, sdf, options, plan.lodProxyLevels, uint8_t(plan.haloLevel + 1),
      [&](uint8_t level, uint64_t key) {
        const uint64_t cell = key >> (3 * (level - plan.cellLevel));
        return cell >= firstCell && cell < endCell;
      },
      0.999 * std::ldexp(1.0, -plan.haloLevel));
  return r;
}

}  // namespace

OctreeChunkPlan planOctreeChunks(const PointSet& points, const RadiusStats& radii,
                                 const BuildOptions& options) {
  OctreeChunkPlan plan;
  plan.firstCell = {0};
  plan.firstPoint = {0, uint32_t(points.size())};
  const double maxEdge = options.maxTestedEdge * radii.spacing;
  if (points.size() <= options.octreeChunkPoints || !(maxEdge > 0.0)) return plan;
  // The coarsest tested level (cells no wider than maxEdge): chunks own cells four times wider, and
  // their halos are cells of that level (half-width halos, measured, let a leaf next to a seam
  // lose points: §15).
  int tested = 0;
  while (tested < kMaxLevel && std::ldexp(1.0, -tested) > maxEdge) ++tested;
  if (tested < 3 || tested > options.maxDepth) return plan;
  plan.haloLevel = uint8_t(tested);
  plan.cellLevel = uint8_t(tested - 2);
  uint64_t inChunk = 0;
  plan.firstPoint.pop_back();
  forEachCell(points, plan.cellLevel, [&](uint64_t cell, uint32_t begin, uint32_t end) {
    if (inChunk > 0 && inChunk + (end - begin) > options.octreeChunkPoints) {
      plan.firstCell.push_back(cell);
      plan.firstPoint.push_back(begin);
      inChunk = 0;
    }
    inChunk += end - begin;
  });
  plan.firstPoint.push_back(uint32_t(points.size()));
  if (plan.chunks() == 1)
    plan.cellLevel = plan.haloLevel = 0;
  else
    plan.lodProxyLevels = lodProxyLevels(points);
  return plan;
}

CornerStageResults runCornerStagesByChunk(const PointSet& points, const OctreeChunkPlan& plan,
                                          const SdfEvaluator& sdf, const BuildOptions& options,
                                          const RadiusStats& radii, CornerStageSeconds& seconds,
                                          ChunkRunStats& stats,
                                          const std::function<void(uint64_t)>& onChunk,
                                          ResumeState* resume, const Ranks* ranks) {
  auto start = Clock::now();
  double* current = nullptr;
  const auto lap = [&](double* next) {
    const auto now = Clock::now();
    if (current != nullptr) *current += std::chrono::duration<double>(now - start).count();
    start = now;
    current = next;
  };
  const auto stage = [&](const char* name) {
    const std::string s = name;
    lap(s == "octree"            ? &seconds.octree
        : s == "passive+balance" ? &seconds.passiveBalance
        : s == "lod"             ? &seconds.lod
                                 : &seconds.corners);
  };
  lap(&seconds.load);
  const std::vector<std::vector<PointRange>> halos = haloRanges(points, plan);
  ChunkMerger merger(points, plan);
  CornerStageResults sum;
  const auto merge = [&](const CornerStageResults& chunk, size_t c) {
    lap(&seconds.merge);
    const PointRange own = {plan.firstPoint[c], plan.firstPoint[c + 1]};
    uint32_t ownLocal = 0;
    for (const PointRange& r : halos[c]) {
      if (r.first < own.first) ownLocal += r.second - r.first;
      stats.haloPoints += r.second - r.first;
    }
    const uint64_t endCell =
        c + 1 < plan.chunks() ? plan.firstCell[c + 1] : uint64_t{1} << (3 * plan.cellLevel);
    merger.add(chunk, c, plan.firstCell[c], endCell, ownLocal, own.first);
    sum.stats.testedPatches += chunk.stats.testedPatches;
    sum.stats.tooFar += chunk.stats.tooFar;
    sum.stats.uncovered += chunk.stats.uncovered;
    sum.stats.thinSplits += chunk.stats.thinSplits;
    sum.passive += chunk.passive;
    sum.splits += chunk.splits;
    sum.trimmed += chunk.trimmed;
    sum.closure.filled += chunk.closure.filled;
    sum.closure.refilled += chunk.closure.refilled;
    sum.closure.passes = std::max(sum.closure.passes, chunk.closure.passes);
    if (onChunk) onChunk(own.second - own.first);
  };
  // A chunk of this process: from the resumed run's checkpoint, or run (and kept for a resume).
  const auto runOwn = [&](size_t c) {
    lap(&seconds.load);
    const std::string checkpoint = octreeChunkCheckpoint(c);
    if (resume != nullptr && resume->has(checkpoint))
      if (std::optional<CornerStageResults> kept = loadCornerStage(*resume, checkpoint)) {
        ++stats.resumed;
        return std::move(*kept);
      }
    CornerStageResults chunk = runChunk(points, c, halos[c], options, radii, plan, stage);
    if (resume != nullptr) saveCornerStage(*resume, chunk, checkpoint);
    return chunk;
  };
  if (ranks == nullptr || ranks->count <= 1) {
    for (size_t c = 0; c < plan.chunks(); ++c) merge(runOwn(c), c);
  } else {
    // Rank 0 runs a chunk whenever one is free and merges, in chunk order, what is done (its
    // own, and the others' from their checkpoints in the shared directory), waiting only when
    // nothing is left to claim. (--resume is refused with ranks.)
    ISO_CHECK(resume == nullptr);
    ResumeState share = sharedState(*ranks);
    std::map<size_t, CornerStageResults> done;  // own chunks run ahead of the merge
    size_t claimFrom = 0;
    for (size_t next = 0; next < plan.chunks();) {
      if (const auto own = done.find(next); own != done.end()) {
        merge(own->second, next);
        done.erase(own);
        ++next;
        continue;
      }
      if (const std::string checkpoint = octreeChunkCheckpoint(next); share.has(checkpoint)) {
        lap(&seconds.load);
        std::optional<CornerStageResults> kept = loadCornerStage(share, checkpoint);
        if (!kept)
          throw std::runtime_error("a rank's results of octree chunk " + std::to_string(next) +
                                   " cannot be read" +
                                   (share.notes().empty() ? "" : ": " + share.notes().back()));
        merge(*kept, next);
        ++next;
        continue;
      }
      while (claimFrom < plan.chunks() && !claimChunk(share, claimFrom)) ++claimFrom;
      if (claimFrom < plan.chunks()) {
        done.emplace(claimFrom, runOwn(claimFrom));
        ++claimFrom;
        continue;
      }
      lap(&seconds.ranks);  // the next chunk is another rank's, still running
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    lap(&seconds.ranks);
    ranks->barrier();
    share.finish();
  }
  lap(&seconds.merge);
  CornerStageResults r = [&] {
    const ProgressMute mute;  // the stage counts points; the seams' new corners are not
    return merger.finish(sdf, options, stats);
  }();
  r.stats = sum.stats;
  r.passive = sum.passive;
  r.splits = sum.splits + stats.seamSplits;
  r.trimmed = sum.trimmed;
  r.closure.filled = sum.closure.filled + stats.seamFills;
  r.closure.refilled = sum.closure.refilled;
  r.closure.passes = sum.closure.passes;
  lap(nullptr);
  return r;
}

void tellRanks(const Ranks& ranks, const PointSet* points, const RadiusStats& radii) {
  std::vector<std::byte> word;
  if (points != nullptr) {
    ResumeState share = sharedState(ranks);
    const std::unique_ptr<CheckpointWriter> out = share.create(kSharedPoints);
    out->json("radii", {radii.spacing, radii.medianRadius});
    writeColumns(*out, *points);
    out->commit();
    word.push_back(std::byte{1});
  }
  ranks.broadcast(word);
}

void runCornerStagesAsRank(const BuildOptions& options, const Ranks& ranks) {
  std::vector<std::byte> word;
  ranks.broadcast(word);
  if (word.empty()) return;  // the octree stages run in one, on rank 0
  ResumeState share = sharedState(ranks);
  PointSet points;
  RadiusStats radii;
  {
    const std::unique_ptr<CheckpointReader> in = share.open(kSharedPoints);
    if (!in)
      throw std::runtime_error("rank 0's points cannot be read from " +
                               share.path(kSharedPoints).string());
    const nlohmann::json r = in->json("radii");
    radii = {r[0].get<double>(), r[1].get<double>()};
    readColumns(*in, points);
    in->finish();
  }
  const OctreeChunkPlan plan = planOctreeChunks(points, radii, options);
  const std::vector<std::vector<PointRange>> halos = haloRanges(points, plan);
  for (size_t c = 0; c < plan.chunks(); ++c)
    if (claimChunk(share, c))
      saveCornerStage(share,
                      runChunk(points, c, halos[c], options, radii, plan, [](const char*) {}),
                      octreeChunkCheckpoint(c));
  ranks.barrier();  // rank 0 has merged every chunk
}

}  // namespace iso
