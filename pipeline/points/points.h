// The points of a conversion and the stages that prepare them, in frame units (the frame's cube
// is [0, 1)^3), one file each:
//
//   frame.cpp     world → frame units, Morton keys, sort, merge exact duplicates
//   knn.cpp       the neighbour index (knn.h): k nearest neighbours, radius and box queries
//   radii.cpp     radius of influence r_i from k nearest neighbours, spacing
//   strays.cpp    stray points: too sparse, or in groups too small to make a surface
//   normals.cpp   PCA normals where the input has none (or invalid ones)
//   orient.cpp    consistent orientation of normals, repair of flipped input normals, roughness
//
// The math, with the paper's equations and every deviation from them, is in specs/pipeline.md.
#pragma once

#include <array>
#include <cstdint>
#include <glm/vec3.hpp>
#include <limits>
#include <span>
#include <vector>

#include "iso/format.h"
#include "iso/surface.h"
#include "pipeline/base/buffers.h"
#include "pipeline/base/options.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

class PointIndex;  // pipeline/points/knn.h

// The points of one processing chunk in frame units, sorted by Morton key after sortByKey().
struct PointSet {
  // Spillable (pipeline/base/buffers.h): out of core, the prepared points of a large input live in
  // mapped files.
  SpillVector<glm::vec3> position;
  SpillVector<glm::vec3> normal;  // unit length, or zero where unknown; empty before normals exist
  SpillVector<glm::vec3> color;   // linear RGB; empty when the input has none
  SpillVector<float> weight;      // input points merged into this one (exact duplicates)
  SpillVector<float> radius;      // radius of influence r_i
  SpillVector<float> roughness;   // RMS distance of the neighbours to the point's tangent plane
  SpillVector<uint64_t> key;      // Morton key at kMaxLevel
  SpillVector<uint32_t> source;   // index of the (first) input point
  size_t size() const { return position.size(); }
  bool hasColors() const { return !color.empty(); }

  // f(sets.column...) for every column above, in that order: the one list of the columns, which
  // the code that sorts, appends, reserves, moves or cuts whole points visits. With two sets,
  // f(a.position, b.position), then the normals, and so on.
  template <typename F, typename... Sets>
  static void forEachColumn(F&& f, Sets&... sets) {
    f(sets.position...);
    f(sets.normal...);
    f(sets.color...);
    f(sets.weight...);
    f(sets.radius...);
    f(sets.roughness...);
    f(sets.key...);
    f(sets.source...);
  }
};

// ---- frame.cpp
// The cube around the points, grown so that surfaces reaching past the outermost points stay
// inside; a degenerate extent (one point, a plane) still gives a positive size.
Frame chooseFrame(const PointCloud& cloud);
// The same from the bounds of the points (lo > hi: no points).
Frame chooseFrame(const glm::dvec3& lo, const glm::dvec3& hi);
// Frame-unit points with keys; normals copied (renormalized; invalid ones set to zero).
PointSet makePointSet(const PointCloud& cloud, const Frame& frame);
glm::dvec3 toFrame(const glm::dvec3& world, const Frame& frame);
glm::dvec3 toWorld(const glm::dvec3& frameUnits, const Frame& frame);
// The frame position of a point of the finest grid.
glm::dvec3 gridToFrame(const GridPoint& p);
// The vector scaled to unit length; zero when it is zero, tiny or not finite.
glm::vec3 unitOrZero(const glm::vec3& n);
// The Morton key at kMaxLevel of a position in frame units (clamped into the cube).
uint64_t keyOf(const glm::vec3& frameUnits);
// The same of a world position: the key the point stages and the out-of-core distribution give
// it (frame units rounded to float first).
inline uint64_t keyOfWorld(const glm::dvec3& world, const Frame& frame) {
  return keyOf(glm::vec3(toFrame(world, frame)));
}
void sortByKey(PointSet& points);
// The order that sorts the keys (stable): order[i] is the index of the i-th smallest.
std::vector<uint32_t> sortedOrder(std::span<const uint64_t> keys);
// Merge points with identical positions into one (weights add, normals and colors average);
// returns how many were merged away. Requires sorted points.
size_t mergeDuplicates(PointSet& points);

// ---- radii.cpp
struct Neighbors {  // the k nearest other points of every point
  int k = 0;
  UninitializedVector<uint32_t> index;  // k per point
  UninitializedVector<float> distance;  // k per point, increasing
};
Neighbors findNeighbors(const PointSet& points, const PointIndex& index, int k);
struct RadiusStats {
  double spacing = 0.0;  // the median distance to the nearest other point
  double medianRadius = 0.0;
};
// r_i = distance to the k-th nearest neighbour; the spacing from the nearest.
RadiusStats estimateRadii(PointSet& points, const Neighbors& neighbors);

// ---- strays.cpp
// The rule that finds stray points (specs/pipeline.md, "Stray points").
// A group (below) of fewer than --stray-group points is a stray, and so is a group whose median
// k-th neighbour distance exceeds the median over all points times max(kSparseFactor,
// e^(kSparseSigmas·σ)), σ the MAD of the log distances as a normal's σ; never a group of half the
// points. Groups, not points, are judged: the sparse end of a scan whose density varies smoothly
// is joined to its dense part and stays.
struct StrayRule {
  static constexpr double kSparseFactor = 32.0, kSparseSigmas = 8.0;
};
// The groups of points that near k-NN edges join (union-find over point ids): an edge i→j, j
// among i's k nearest, joins when no longer than 3 times the smaller of their k-th distances.
class PointGroups {
 public:
  explicit PointGroups(size_t ids);
  // Join points [begin, end) to their near neighbours, point i named `first + i - begin`. An edge
  // to a neighbour outside [begin, end) is not joined but appended to `outside` as (the point's
  // name, the neighbour's index) for the caller, who knows its name, to join.
  void joinNeighbors(const Neighbors& neighbors, uint32_t begin, uint32_t end, uint32_t first,
                     SpillVector<std::array<uint32_t, 2>>& outside);
  void join(uint32_t a, uint32_t b);
  uint32_t root(uint32_t id);

 private:
  SpillVector<uint32_t> parent_;
};
struct Strays {
  std::vector<uint8_t> flagged;  // per point
  size_t sparse = 0;             // in groups far sparser than the scan
  size_t grouped = 0;            // in groups of fewer than groupPoints
};
// The median k-th distance beyond which a group is sparse (StrayRule).
float sparseThreshold(std::span<const float> kth);
// Strays among points 0 … kth.size() - 1 with these k-th distances, grouped in `groups` (under
// their own numbers). Memory beyond the flags: spilled arrays of a word a point.
Strays flagStrays(std::span<const float> kth, PointGroups& groups, uint32_t groupPoints);
// Strays among n points with these neighbours, in core.
Strays findStrays(size_t n, const Neighbors& neighbors, uint32_t groupPoints);
// The positions (frame units) of stray points: an input point at one of them (a duplicate merged
// into a stray) is a stray too.
class StrayPositions {
 public:
  void add(const glm::vec3& p) { bits_.push_back(bitsOf(p)); }
  void seal();  // after the last add
  bool contains(const glm::vec3& p) const;

 private:
  using Bits = std::array<uint32_t, 3>;
  static Bits bitsOf(const glm::vec3& p);
  std::vector<Bits> bits_;
};
// The cloud without the input points at the positions (frame units) of the flagged ones of
// `points` (so duplicates merged into a stray go too); those go to `removed` when given.
PointCloud withoutFlagged(const PointCloud& cloud, const Frame& frame, const PointSet& points,
                          std::span<const uint8_t> flagged, PointCloud* removed = nullptr);
// The cloud without its strays, found as a conversion finds them (k neighbours, groups of fewer
// than groupPoints): what `iso eval` measures against a file's input points.
PointCloud withoutStrays(const PointCloud& cloud, int k, uint32_t groupPoints);
// The median of values (reordered); 0 for none.
float medianOf(std::span<float> values);

// ---- normals.cpp / orient.cpp
struct NormalStats {
  size_t estimated = 0;  // normals computed by PCA
  size_t flipped = 0;    // input normals flipped to agree with their neighbourhood
};
// PCA normals (in double, stable symmetric eigen solver) for every point whose normal is zero.
size_t estimateNormals(PointSet& points, const Neighbors& neighbors);
// Orient estimated normals consistently (mode) and repair isolated flipped input normals.
// Propagation runs in blocks (the coarsest Morton cells of at most blockPoints key-sorted points),
// then flips whole components to agree across blocks: local, so out-of-core chunks orient alike.
NormalStats orientNormals(PointSet& points, const Neighbors& neighbors, OrientMode mode,
                          const std::vector<uint8_t>& wasEstimated,
                          size_t blockPoints = BuildOptions{}.orientBlockPoints);
// The phases of orientNormals, for the out-of-core conversion:
// Orientation blocks among key-sorted points [begin, end), which lie in one cell of `level`.
using OrientationBlocks = std::vector<std::array<uint32_t, 2>>;
OrientationBlocks orientationBlocks(const PointSet& points, size_t maxPoints, uint32_t begin,
                                    uint32_t end, int level);
// Flip input normals that contradict their neighbours (repeated); returns how many flips there
// were among points [countBegin, countEnd).
size_t repairFlippedNormals(PointSet& points, const Neighbors& neighbors,
                            const std::vector<uint8_t>& wasEstimated, uint32_t countBegin = 0,
                            uint32_t countEnd = std::numeric_limits<uint32_t>::max());
// Turn estimated normals of points [begin, end) up (--orient up).
void orientUp(PointSet& points, const std::vector<uint8_t>& wasEstimated, uint32_t begin,
              uint32_t end);
// Components of the propagation: each block's parts, numbered block by block.
struct OrientationComponents {
  SpillVector<uint32_t> of;       // per point: its component
  std::vector<uint8_t> anchored;  // per component: holds input normals (never flipped)
  std::vector<float> seedVote;  // per component: its points × its seed normal's z (0 if anchored)
};
// Propagate inside each block; points of the blocks get components numbered after those already
// in `components` (whose `of` covers all points).
void propagateInBlocks(PointSet& points, const Neighbors& neighbors,
                       const std::vector<uint8_t>& wasEstimated, const OrientationBlocks& blocks,
                       OrientationComponents& components);
// Flip whole components to agree across the k-NN edges between them (neighborIndex: k per
// point): a maximum spanning forest; a forest with anchored components keeps their signs, any
// other takes the sign its components vote for.
void alignComponents(std::span<glm::vec3> normals, const OrientationComponents& components,
                     std::span<const uint32_t> neighborIndex, size_t k);
// The same over the edges of some points only (neighborIndex: k per point of `from`), which must
// include every edge between two components (the sums are the same: edges inside a component
// add nothing).
void alignComponents(std::span<glm::vec3> normals, const OrientationComponents& components,
                     std::span<const uint32_t> from, std::span<const uint32_t> neighborIndex,
                     size_t k);
// Local roughness (noise, and curvature below the neighbourhood's scale) of every point: the RMS
// distance of its neighbours to the plane through their centroid with the point's normal.
void estimateRoughness(PointSet& points, const Neighbors& neighbors);
// The roughness of point i from its k neighbours.
float roughnessOf(const PointSet& points, uint32_t i, const uint32_t* neighbors, size_t k);
}  // namespace iso
