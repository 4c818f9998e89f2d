// The signed distance sampled at the corners of the octree's filled leaves and of its internal
// nodes (levels of detail), one file each:
//
//   corners.cpp   leaf corner sampling: each distinct corner evaluated once
//   snap.cpp      hanging corners snapped to the coarser neighbour's face or edge (crack-free)
//   fit.cpp       corner values fitted to the points (the trilinear patch's bias undone)
//   close.cpp     closure: empty cells the surface runs into are filled, until none is left
//   trim.cpp      trimming: leaves whose surface lies mostly far from every point are emptied
//   lod.cpp       level of detail: corners of internal nodes from point proxies, node errors
//
// The octree and the field depend on each other (the octree's patch tests fill the field; the
// field follows the tree's leaves), hence one folder. The math is in specs/pipeline.md.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <utility>
#include <vector>

#include "iso/flat_map.h"
#include "iso/format.h"
#include "iso/surface.h"
#include "pipeline/base/buffers.h"
#include "pipeline/base/options.h"
#include "pipeline/octree/cell_index.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/points.h"

static_assert(iso::KeyIndex<iso::Key128>::kNone == iso::kNoNode);
static_assert(iso::CellKeyIndex::kNone == iso::kNoNode);

namespace iso {

// ---- corners.cpp
// Values at grid points, each evaluated once: the corners of the nodes the octree tested, then of
// every filled leaf.
inline constexpr uint8_t kUnusedCorner = 0xff;  // coarsestLevel of a corner no filled leaf uses
Key128 gridKey(const GridPoint& p);
struct CornerField {
  CornerField() = default;
  // A table for about `expected` corners, and arrays reserved for `reserved` (address space:
  // pages count once written; below that the arrays never grow by copying).
  CornerField(size_t expected, size_t reserved);
  // Spillable (pipeline/base/buffers.h): the entries are made in the key order of the leaves using
  // them, which the stages that read them follow; so are the index's keys and table.
  CellKeyIndex index{1024};            // gridKey → entry
  SpillVector<uint8_t> coarsestLevel;  // of the filled leaves using the corner, or kUnusedCorner
  SpillVector<CornerSample> value;
  uint32_t find(const GridPoint& p) const;
  uint32_t find(const Key128& key) const { return index.find(key); }
  GridPoint point(uint32_t entry) const;
  size_t size() const { return index.size(); }
  // The entry of key, added when new (value to be set, no leaf using it); second: whether added.
  std::pair<uint32_t, bool> insert(const Key128& key);
};
// Set the coarsest levels of a field's corners from the tree's filled leaves now (kUnusedCorner
// for corners no filled leaf uses, such as those of leaves split since); returns the number of
// corners in use.
size_t refreshCornerLevels(CornerField& field, const Octree& tree);
// Evaluate the signed distance at the field's entries (in parallel).
void evaluateCorners(CornerField& field, std::span<const uint32_t> entries,
                     const SdfEvaluator& sdf);
// Add the corners of filled leaves to a field (their coarsest levels updated), evaluating those it
// does not hold yet.
void addLeafCorners(CornerField& field, const Octree& tree, std::span<const uint32_t> leaves,
                    const SdfEvaluator& sdf);

// ---- snap.cpp
struct HangingCorner {
  uint32_t corner;                    // entry in the CornerField
  std::array<uint32_t, 4> sources{};  // the coarser leaf's corners it interpolates
  uint8_t sourceCount = 0;            // 2 (edge) or 4 (face)
};
using HangingCorners = SpillVector<HangingCorner>;  // in the field's entry order, then by level
HangingCorners findHangingCorners(const Octree& tree, const CornerField& field);
// Set each hanging corner to the mean of its sources, coarse levels first.
void snapHangingCorners(CornerField& field, const HangingCorners& hanging);

// ---- fit.cpp
// Move the corners of the leaves that hold points by the mean distance of the points around them
// from the interpolated zero set, `passes` times (hanging corners snapped after each); returns the
// corners moved in the last pass.
size_t fitCornersToPoints(CornerField& field, const HangingCorners& hanging, const Octree& tree,
                          const PointSet& points, int passes);

// ---- close.cpp
struct Closure {
  CornerField corners;
  HangingCorners hanging;
  size_t cornersInUse = 0;  // corners of the final filled leaves
  size_t filled = 0;        // empty cells filled because the surface ran into them
  size_t refilled = 0;      // ... of them, by closeAgain
  size_t passes = 0;
};
// Sample the leaf corners, snap hanging corners, and fill the empty cells next to points into
// which the zero set of a filled leaf runs (sharp edges, repaired normals), until none is left:
// near the points the surface never leaves the filled leaves, so rays cannot slip out of it.
// `corners` holds the values evaluated while building; it becomes the closure's field.
Closure sampleClosedSurface(Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                            CornerField&& corners);
// Close the surface again after its corners moved (the corner fit carries the zero set of some
// leaves out through faces the first closure saw it stay behind): the same passes, from the
// filled leaves one of whose corners changed sign (`wasNegative`, by corner entry, before the
// move); the cells they fill get sampled corners.
void closeAgain(Octree& tree, const PointSet& points, const SdfEvaluator& sdf, Closure& closure,
                const std::vector<uint8_t>& wasNegative);
// The filled leaves that have the grid point p as a corner, each once; returns how many.
size_t filledLeavesAt(const Octree& tree, const GridPoint& p, std::array<uint32_t, 8>& out);
// After the tree's filled leaves changed: the corner levels set from the final leaves (every
// corner they use is in the field), the hanging corners found again and snapped.
void refreshCorners(const Octree& tree, Closure& closure);
// The same where the filled leaves changed only at the `changed` nodes (leaves emptied or filled,
// filled leaves split, new ones) and the levels, hanging corners and snapped values are up to date
// everywhere else, except at the corners of the `cornersOf` leaves (snap.cpp): only the corners
// those nodes touch are looked at, with the same result as refreshCorners over the whole tree.
void refreshCornersAround(const Octree& tree, Closure& closure, std::span<const uint32_t> changed,
                          std::span<const uint32_t> cornersOf = {});
// Whether each node is a filled leaf now, and the nodes for which that differs from such a
// snapshot (nodes added since included): the `changed` nodes of refreshCornersAround.
std::vector<uint8_t> filledNodes(const Octree& tree);
std::vector<uint32_t> nodesChangedSince(const Octree& tree, const std::vector<uint8_t>& filled);
// The order of the hanging corners: coarse first (a source may itself hang from a leaf another
// level up), then by entry.
bool hangsBefore(const CornerField& field, const HangingCorner& a, const HangingCorner& b);
// Whether the closure fills the empty cell (level, key) that the zero set of the leaf (leafLevel,
// leafKey) runs into.
using ExitFilter =
    std::function<bool(uint8_t leafLevel, uint64_t leafKey, uint8_t level, uint64_t key)>;
// Close the surface from these filled leaves (where a chunk run's jobs met): their missing corners
// sampled, then the closure's passes from them (the first pass filling only the cells `firstPass`
// accepts, when given). The cells it fills are counted in closure.filled. The corner levels and
// hanging corners are left for the caller to refresh (refreshCornersAround the leaves that
// changed).
void closeFromLeaves(std::vector<uint32_t> leaves, Octree& tree, const PointSet& points,
                     const SdfEvaluator& sdf, Closure& closure, const ExitFilter& firstPass = {});

// ---- trim.cpp
// Empty the filled leaves without points whose zero set exists and lies, at half or more of the
// places where it is sampled, farther than `reach` radii of influence from the nearest point
// (sheets across holes), and the internal nodes left with nothing filled below; the closure's
// corner levels and hanging corners are updated. Returns the leaves emptied. With `candidates`,
// only those leaves are looked at.
size_t trimFarSurface(Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                      Closure& closure, double reach,
                      const std::vector<uint32_t>* candidates = nullptr);

// ---- lod.cpp
// Corners of internal nodes, keyed by (level, grid point), evaluated from point proxies.
struct LodField {
  CellKeyIndex index{1024};  // lodKey → entry
  SpillVector<CornerSample> value;
  size_t fromSamples = 0;  // entries whose value came from sampleLodCorners' `known`
  uint32_t find(uint8_t level, const GridPoint& p) const;
  GridPoint point(uint32_t entry) const;
};
Key128 lodKey(uint8_t level, const GridPoint& p);
// One level-of-detail corner's value under its key (lodKey), as a chunk job gives it.
struct LodSample {
  Key128 key;
  CornerSample value;
};
// For each node level, the level of the proxies its corners are evaluated from, or -1 where they
// are evaluated from the points: a function of all the points (sorted by key).
using LodProxyLevels = std::array<int8_t, kMaxLevel + 1>;
LodProxyLevels lodProxyLevels(const PointSet& points);
// pointsSdfDone, when set, is called once pointsSdf is no longer needed (before any proxies are
// made), so that it and its index can be freed. With a cut (a chunk run's parts, whose nodes come
// in part order), each part's corners get their own stretch of the field's table. Corners with a
// value in `known` take it (the first one where several have the same key) and are not evaluated.
// `proxyLevels`: lodProxyLevels(points) when the caller has them (else made here).
LodField sampleLodCorners(const Octree& tree, const PointSet& points, const SdfEvaluator& pointsSdf,
                          const BuildOptions& options,
                          const std::function<void()>& pointsSdfDone = {}, const CellCut& cut = {},
                          const SpillVector<LodSample>* known = nullptr,
                          const LodProxyLevels* proxyLevels = nullptr);
// A chunk job's share of the level of detail: the corners of the internal nodes of `tree` at
// levels >= minLevel for which owned(level, key) holds, each evaluated as sampleLodCorners
// evaluates it over all points (the proxies of `proxyLevels`) where that reads no point farther
// than `reach` from the corner (SdfEvaluator::evaluateWithin), in (level, key) order; the others
// are left to sampleLodCorners. `points` (sorted by key) must hold every point of all points
// within `reach` of each owned node's corners, and whole cells at the proxy levels.
SpillVector<LodSample> sampleLodCornersWithin(
    const Octree& tree, const PointSet& points, const SdfEvaluator& pointsSdf,
    const BuildOptions& options, const LodProxyLevels& proxyLevels, uint8_t minLevel,
    const std::function<bool(uint8_t level, uint64_t key)>& owned, double reach);
// The largest distance of the points below an internal node to the node's own patch.
float nodePatchError(const Octree& tree, const PointSet& points, const LodField& lod,
                     uint32_t node);
}  // namespace iso
