// The adaptive octree over the points and the signed distance it is fitted to, one file each:
//
//   sdf.cpp       the signed distance at a corner (truncated Gaussian plane or sphere fit)
//   octree.cpp    adaptive octree: point count, error-driven tolerance, coverage, thin sheets
//   passive.cpp   passive leaves: empty cells inside a point's disk of influence
//   balance.cpp   2:1 balance between face-, edge- and corner-adjacent filled leaves
//
// The values sampled at the tree's corners are in field.h. The math is in specs/pipeline.md. All
// positions are in frame units.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <glm/vec3.hpp>
#include <optional>
#include <vector>

#include "iso/format.h"
#include "pipeline/base/buffers.h"
#include "pipeline/base/options.h"
#include "pipeline/points/points.h"

namespace iso {

// How corner distances are stored: snorm8, 1.0 = one node diagonal (specs/pipeline.md, §7).
inline constexpr AttributeDesc kDistanceEncoding{Semantic::SignedDistance, Encoding::Snorm8, 1,
                                                 1.0f};

// ---- sdf.cpp
struct CornerSample {
  float distance = 0.0f;
  glm::vec3 normal{0.0f, 0.0f, 1.0f};
  glm::vec3 color{0.0f};
};
// f(Q) = (Q - p̄)·n̄ with truncated Gaussian weights (specs/pipeline.md, "Signed distance").
class SdfEvaluator {
 public:
  SdfEvaluator(const PointSet& points, const PointIndex& tree, double smoothing, FitMode fit);
  // minSigma widens every σ_i (level of detail: a fraction of the node size).
  CornerSample evaluate(const glm::dvec3& q, float minSigma) const;
  // The same, or nullopt when it would read points farther than `reach` from q: evaluated over a
  // subset of the points that holds every point within `reach` of q, it then gives what the whole
  // set gives (up to the order of the sums).
  std::optional<CornerSample> evaluateWithin(const glm::dvec3& q, float minSigma,
                                             double reach) const;
  // The point nearest to q and its distance.
  uint32_t nearest(const glm::dvec3& q, float& distance) const;
  const PointSet& points() const { return points_; }

 private:
  const PointSet& points_;
  const PointIndex& tree_;
  double smoothing_;
  FitMode fit_;
  std::optional<CornerSample> sample(const glm::dvec3& q, float minSigma, double reach) const;
  // 1 / 2(smoothing · r_i)², in float (computed when needed rather than stored: 4 bytes a point).
  float halfInverseSigma2(uint32_t i) const {
    const double sigma = smoothing_ * double(points_.radius[i]);
    return sigma > 0.0 ? float(0.5 / (sigma * sigma)) : HUGE_VALF;
  }
};

// ---- octree.cpp
// The trilinear patch of one node: its 8 corner distances over its cell.
struct Patch {
  std::array<double, 8> distance{};
  glm::dvec3 origin{0.0};
  double size = 1.0;
  Patch() = default;
  Patch(uint8_t level, uint64_t key);  // the cell of a node, distances zero
  // The signed distance at p (clamped into the cell) and, when asked, its gradient.
  double value(const glm::dvec3& p, glm::dvec3* gradient = nullptr) const;
  // The largest |f|/|∇f| over points [begin, end): how far they are from the zero set.
  double maxPointDistance(const PointSet& points, uint32_t begin, uint32_t end) const;
};

enum class NodeKind : uint8_t { Empty, Internal, Leaf, Passive };

struct OctreeNode {
  uint64_t key = 0;
  uint32_t firstChild = kNoNode;  // Internal: 8 children in octant order
  uint32_t pointBegin = 0, pointEnd = 0;
  uint8_t level = 0;
  NodeKind kind = NodeKind::Empty;
  float maxRadius = 0.0f;  // largest r_i of the points below (disk queries)
  bool isFilled() const { return kind == NodeKind::Leaf || kind == NodeKind::Passive; }
  uint32_t pointCount() const { return pointEnd - pointBegin; }
};

struct Octree {
  // Node 0: the root (level 0). Nodes are made a level at a time in key order, and balance and
  // closure add theirs in key order: spillable (pipeline/base/buffers.h).
  SpillVector<OctreeNode> nodes;
  // Make the cell (level, key) a node, splitting empty nodes above it; returns the node there or
  // the filled or internal node that holds it.
  uint32_t materialize(uint8_t level, uint64_t key, const PointSet& points);
  // The deepest node on the path to cell (level, key), at most at that level.
  uint32_t find(uint8_t level, uint64_t key) const;
  // Make a filled node Internal with 8 children over its points (kinds: Leaf with points, else
  // Empty).
  void split(uint32_t node, const PointSet& points);
  // Whether test(pointIndex) holds for some point whose disk of influence may touch the box
  // (frame units); the search stops at the first.
  bool anyPointNear(const glm::dvec3& lo, const glm::dvec3& hi, const PointSet& points,
                    const std::function<bool(uint32_t)>& test) const;
  void updateMaxRadius(const PointSet& points);
};

struct OctreeStats {
  size_t testedPatches = 0;  // patch tests that led to a subdivision
  size_t tooFar = 0;         // ... because points were farther than the tolerance
  size_t uncovered = 0;      // ... because the patch had surface where there are no points
  size_t thinSplits = 0;     // subdivisions below leafPoints for opposing normals
};
struct CornerField;
// The corners of tested nodes are evaluated into `corners` (leaf corners are evaluated the same way
// whatever the level, so the final leaf corners reuse them).
Octree buildOctree(const PointSet& points, const SdfEvaluator& sdf, const BuildOptions& options,
                   const RadiusStats& radii, CornerField& corners, OctreeStats* stats = nullptr);

// ---- passive.cpp
// Whether the disk of point i (center, normal, radius r_i) touches the box.
bool diskTouchesBox(const PointSet& points, uint32_t i, const glm::dvec3& lo, const glm::dvec3& hi);
bool isCoveredByDisk(const Octree& tree, const PointSet& points, uint32_t node);
// Mark Empty children of Internal nodes at minLevel or deeper Passive when a disk touches them;
// returns how many. (A chunk run marks none above the level its chunks own cells of.)
size_t markPassiveLeaves(Octree& tree, const PointSet& points, uint8_t minLevel = 0);

// ---- balance.cpp
// Split filled leaves until face-, edge- and corner-adjacent filled leaves differ by at most one
// level; returns the number of splits.
size_t balanceOctree(Octree& tree, const PointSet& points);
// The same after filling the leaves `added` in a balanced tree: only they and their neighbours are
// checked. The filled leaves that splits create are appended to `created`.
size_t balanceAfter(Octree& tree, const PointSet& points, const std::vector<uint32_t>& added,
                    std::vector<uint32_t>& created);

}  // namespace iso
