// The stages that turn points into an Implicit Surface Octree, one file each, in pipeline order:
//
//   buffers.cpp   large arrays without zeroing, on huge pages
//   frame.cpp     world → frame units, Morton keys, sort, merge exact duplicates
//   radii.cpp     radius of influence r_i from k nearest neighbours, outliers, mean spacing
//   normals.cpp   PCA normals where the input has none (or invalid ones)
//   orient.cpp    consistent orientation of normals; repair of flipped input normals
//   sdf.cpp       the signed distance estimator at a corner (truncated Gaussian plane fit)
//   octree.cpp    adaptive octree: point count, error-driven tolerance, coverage, thin sheets
//   passive.cpp   passive leaves: empty cells inside a point's disk of influence
//   balance.cpp   2:1 balance between face-, edge- and corner-adjacent filled leaves
//   corners.cpp   leaf corner sampling: each distinct corner evaluated once
//   snap.cpp      hanging corners snapped to the coarser neighbour's face or edge (crack-free)
//   lod.cpp       level of detail: corners of internal nodes from point proxies, chunk errors
//   texture.cpp   triplanar textures baked at the points or at the corners
//   chunks.cpp    cutting the octree into file chunks, quantization, writing through format/
//   occlusion.cpp ambient occlusion traced against the written surface, baked into corners
//
// The math, with the paper's equations and every deviation from them, is in specs/pipeline.md.
// All stages work in frame units: the frame's cube is [0, 1)^3.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <glm/vec3.hpp>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "buffers.h"
#include "io/point_cloud.h"
#include "iso/flat_map.h"
#include "iso/format.h"
#include "iso/surface.h"
#include "occlusion.h"
#include "texture.h"

static_assert(iso::KeyIndex<iso::Key128>::kNone == iso::kNoNode);

namespace iso {

class PointIndex;

enum class OrientMode { Auto, Up, Propagate };
// The local surface fitted at a corner: the paper's plane, or an algebraic sphere (APSS,
// Guennebaud & Gross 2007), which has no curvature bias (specs/pipeline.md measures both).
enum class FitMode { Plane, Sphere };

// How corner distances are stored: snorm8, 1.0 = one node diagonal (specs/pipeline.md, §7).
inline constexpr AttributeDesc kDistanceEncoding{Semantic::SignedDistance, Encoding::Snorm8, 1,
                                                 1.0f};

struct BuildOptions {
  int neighbors = 10;      // k of the k-NN radius r_i (and of PCA normals)
  double smoothing = 1.0;  // σ_i = smoothing · r_i
  FitMode fit = FitMode::Sphere;
  OrientMode orient = OrientMode::Auto;
  uint32_t leafPoints = 8;      // a node with more points may be subdivided
  // A node with more points is subdivided without a patch test. Not a command-line option: tests
  // lower it so that small scans have chunks many tested nodes wide, as large scans do.
  uint32_t maxTestedPoints = 4096;
  // A node wider than this many mean spacings is subdivided without a patch test, so that no test
  // reads points much farther than that from its node (out-of-core chunks need reads of bounded
  // reach). Not a command-line option.
  double maxTestedEdge = 128.0;
  int maxDepth = 20;            // deepest octree level (at most 20)
  double tolerance = 0.1;       // allowed patch error, in mean point spacings
  int normalBits = 8;           // octahedral normal bits per component: 8 or 12
  uint32_t chunkNodes = 32768;  // octree nodes per file chunk, about
  int zstdLevel = 3;
  bool removeOutliers = true;
  // Points per orientation block (orientNormals); part of the result, so a parameter.
  uint32_t orientBlockPoints = 1u << 20;
  TextureOptions texture;      // a triplanar texture baked into the colors (texture.h)
  OcclusionOptions occlusion;  // ambient occlusion baked into the corners (occlusion.h)
  // The input points kept in points chunks (keep_points.h), positions to 2^-pointBits of the
  // frame.
  bool keepPoints = false;
  int pointBits = 24;
  // Points per points chunk, about (kPointsPerChunk). Not a command-line option: tests lower it
  // so that small scans have many chunks.
  uint32_t keptPointsPerChunk = 1u << 16;
};

// The points of one processing chunk in frame units, sorted by Morton key after sortByKey().
struct PointSet {
  // Spillable (buffers.h): out of core, the prepared points of a large input live in mapped files.
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
  double meanSpacing = 0.0;  // mean distance to the nearest other point
  double medianRadius = 0.0;
  size_t outliers = 0;  // removed by removeOutliers
};
// r_i = distance to the k-th nearest neighbour; mean spacing from the nearest.
RadiusStats estimateRadii(PointSet& points, const Neighbors& neighbors);
// Points whose radius exceeds 10 times the median radius of their neighbours (far outliers).
std::vector<uint8_t> findOutliers(const PointSet& points, const Neighbors& neighbors);
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

inline constexpr uint8_t kMaxClosurePasses = 8;  // close.cpp

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
  // The point nearest to q and its distance.
  uint32_t nearest(const glm::dvec3& q, float& distance) const;
  const PointSet& points() const { return points_; }

 private:
  const PointSet& points_;
  const PointIndex& tree_;
  double smoothing_;
  FitMode fit_;
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
  // closure add theirs in key order: spillable (buffers.h).
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
// Mark Empty children of Internal nodes Passive when a disk touches them; returns how many.
size_t markPassiveLeaves(Octree& tree, const PointSet& points);

// ---- balance.cpp
// Split filled leaves until face-, edge- and corner-adjacent filled leaves differ by at most one
// level; returns the number of splits.
size_t balanceOctree(Octree& tree, const PointSet& points);
// The same after filling the leaves `added` in a balanced tree: only they and their neighbours are
// checked. The filled leaves that splits create are appended to `created`.
size_t balanceAfter(Octree& tree, const PointSet& points, const std::vector<uint32_t>& added,
                    std::vector<uint32_t>& created);

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
  // Spillable (buffers.h): the entries are made in the key order of the leaves using them, which
  // the stages that read them follow; the hash table stays in memory.
  KeyIndex<Key128, SpillAllocator<Key128, true>> index{1024};  // gridKey → entry
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

// ---- close.cpp
struct Closure {
  CornerField corners;
  HangingCorners hanging;
  size_t cornersInUse = 0;  // corners of the final filled leaves
  size_t filled = 0;        // empty cells filled because the surface ran into them
  size_t passes = 0;
};
// Sample the leaf corners, snap hanging corners, and fill the empty cells next to points into
// which the zero set of a filled leaf runs (sharp edges, repaired normals), until none is left:
// near the points the surface never leaves the filled leaves, so rays cannot slip out of it.
// `corners` holds the values evaluated while building; it becomes the closure's field.
Closure sampleClosedSurface(Octree& tree, const PointSet& points, const SdfEvaluator& sdf,
                            CornerField&& corners);

// ---- lod.cpp
// Corners of internal nodes, keyed by (level, grid point), evaluated from point proxies.
struct LodField {
  KeyIndex<Key128, SpillAllocator<Key128, true>> index{1024};  // lodKey → entry
  SpillVector<CornerSample> value;
  uint32_t find(uint8_t level, const GridPoint& p) const;
  GridPoint point(uint32_t entry) const;
};
Key128 lodKey(uint8_t level, const GridPoint& p);
// pointsSdfDone, when set, is called once pointsSdf is no longer needed (before any proxies are
// made), so that it and its index can be freed.
LodField sampleLodCorners(const Octree& tree, const PointSet& points, const SdfEvaluator& pointsSdf,
                          const BuildOptions& options,
                          const std::function<void()>& pointsSdfDone = {});
// The largest distance of the points below an internal node to the node's own patch.
float nodePatchError(const Octree& tree, const PointSet& points, const LodField& lod,
                     uint32_t node);

// ---- chunks.cpp
struct ChunkPlan {
  uint8_t cellLevel = 0;
  uint64_t cellKey = 0;
  uint32_t parent = kNoParent;
  SurfaceTopology topology;
  std::vector<uint32_t> nodes;  // octree nodes in topology order
  uint64_t pointCount = 0;      // input points below the roots
};
std::vector<ChunkPlan> planChunks(const Octree& tree, uint32_t nodeBudget);

struct WriteInput {
  const Octree* tree;
  const PointSet* points;
  const CornerField* corners;
  const HangingCorners* hanging;
  const LodField* lod;
  Frame frame;
  std::string metadata;  // JSON object
  bool colors = false;
  BuildOptions options;
  std::function<void()> release =
      {};  // when set, called once every chunk is written (frees the above)
  // When set, the written file is copied by it into a second writer (whose header is
  // withOcclusion's), which becomes the output: ambient occlusion needs the finished surface.
  std::function<void(const Reader& written, Writer& output)> occlusion = {};
  // When set, called after the surface chunks (and `release`) to add chunks of other kinds.
  std::function<void(Writer& output, const FileHeader& header)> moreChunks = {};
};
struct WriteStats {
  uint64_t chunks = 0, fileBytesWithoutMetadata = 0;
  uint64_t leafCorners = 0, lodCorners = 0;
};
FileHeader surfaceHeader(const Frame& frame, uint8_t maxLevel, bool colors, int normalBits);
// Plan chunks, encode and write the file with input.metadata. Before the file is moved to the
// output path, `finalMetadata` gets the complete file (under its temporary name, readable with
// iso::Reader) and the stats, and returns the metadata that replaces the first.
WriteStats writeSurfaceFile(const std::filesystem::path& output, const WriteInput& input,
                            const std::function<std::string(const std::filesystem::path&,
                                                            const WriteStats&)>& finalMetadata);

}  // namespace iso
