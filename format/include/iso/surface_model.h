// The finest surface of an .iso file in memory, with the queries that measure and draw it: the
// filled leaf containing a point, the trilinear signed distance and its gradient, ray hits
// (octree traversal and the root of the cubic along the ray), projection of points onto the zero
// set, and area-weighted samples of the zero set. Coordinates are frame units: the frame's cube is
// [0, 1)^3.
//
// Threading: after load(), all const member functions may run from many threads at once.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "iso/flat_map.h"
#include "iso/format.h"
#include "iso/surface.h"

namespace iso {

class Reader;

using Vec3 = std::array<double, 3>;

struct SurfaceEval {
  double distance = 0.0;          // the trilinear signed distance
  Vec3 gradient{};                // its gradient
  std::array<float, 3> normal{};  // interpolated stored normal, or the gradient's direction
  std::array<float, 3> color{};   // interpolated linear color (zero when the file has none)
  std::array<float, 3> irradiance{};  // interpolated baked irradiance (zero when none)
};

struct RayHit {
  double t = 0.0;
  uint32_t leaf = kNoNode;
};

struct ZeroSetSample {
  Vec3 position{};
  double area = 0.0;  // the area of the zero set this sample stands for
  uint32_t leaf = kNoNode;
};

class SurfaceModel {
 public:
  struct Leaf {
    uint64_t key = 0;
    uint8_t level = 0;
    std::array<uint32_t, kCorners> corners{};  // into the model's corner arrays
  };

  // A box in frame units (closed).
  struct Region {
    Vec3 lo{}, hi{};
    bool contains(const Vec3& p) const;
    bool meetsCell(uint8_t level, uint64_t key) const;
  };

  // Decode every surface chunk of the file and link them into one octree. Throws iso::FileError
  // for invalid chunks and when chunks overlap or leave a cut node without its children. With a
  // region, only the chunks whose cells meet it: every leaf that meets the region is there, and
  // the queries answer inside it as the whole model does (project() says when a query left it).
  // `source`, when set, gives the decoded chunks (a cache of those that many regions share).
  // With cutLevel below the file's deepest level: the surface a level-of-detail cut at that level
  // draws: leaves at or above it, and the internal nodes at it as leaves with their own (LOD)
  // corners.
  using ChunkSource = std::function<std::shared_ptr<const SurfaceChunk>(uint32_t id)>;
  static SurfaceModel load(const Reader& reader, const std::optional<Region>& region = {},
                           const ChunkSource& source = {}, uint8_t cutLevel = kMaxLevel);
  // The surface chunks load() decodes for a region and cut level, in file order.
  static std::vector<uint32_t> chunksFor(const Reader& reader, const std::optional<Region>& region,
                                         uint8_t cutLevel = kMaxLevel);

  const FileHeader& header() const { return header_; }
  std::span<const Leaf> leaves() const { return leaves_; }
  bool hasNormals() const { return !corners_.normal.empty(); }
  bool hasColors() const { return !corners_.color.empty(); }
  // The file has lighting chunks (iso/lighting.h): corners() carries their irradiance.
  bool hasIrradiance() const { return !corners_.irradiance.empty(); }
  const CornerValues& corners() const { return corners_; }
  // Where each of the model's corners comes from: a leaf corner (or, for the internal nodes of a
  // level-of-detail cut, an LOD corner) of a surface chunk, by its number there. A corner shared
  // by chunks is a corner of the model once per chunk.
  struct CornerSource {
    uint32_t chunk = 0, corner = 0;
    bool lod = false;
  };
  std::span<const CornerSource> cornerSources() const { return sources_; }

  // The filled leaf that contains p, or kNoNode in empty space and outside the frame.
  uint32_t findLeaf(const Vec3& p) const;
  SurfaceEval evaluate(uint32_t leaf, const Vec3& p) const;
  // With irradiance: the irradiance of a leaf's corner (its own where the file overrides it).
  const std::array<float, 3>& irradianceAt(uint32_t leaf, int corner) const;
  // The trilinear weights of the leaf's corners (Leaf::corners) at p (clamped into it).
  std::array<double, 8> cornerWeights(uint32_t leaf, const Vec3& p) const;
  // The trilinear signed distance in a leaf at p (clamped into it), and its gradient in frame
  // units when asked: evaluate() without the normal and color.
  double distanceAt(uint32_t leaf, const Vec3& p, std::array<double, 3>* gradient = nullptr) const;

  // The first hit of the ray origin + t·direction with t in [tMin, tMax]. A sign change between
  // the exit of one leaf and the entry of the next counts as a hit, so that no mismatch below the
  // quantization step can let a ray through.
  std::optional<RayHit> intersect(const Vec3& origin, const Vec3& direction, double tMin,
                                  double tMax) const;

  // A point of the zero set near p, by Newton steps along the gradient, or where a step changes
  // the sign of f (found by bisection: a root inside a leaf or a sign change at a leaf face); none
  // when the steps leave the filled leaves or do not converge.
  // With a region (load), `escaped` is set when the steps left it: the answer may then differ from
  // the whole model's.
  std::optional<Vec3> project(const Vec3& p, bool* escaped = nullptr) const;

  // Points of the zero set: roots along axis-aligned lines, `linesPerEdge` per leaf edge, each kept
  // by the axis most aligned with the gradient and weighted by the area it stands for.
  std::vector<ZeroSetSample> sampleZeroSet(int linesPerEdge) const;
  // The same, in the given leaves only.
  std::vector<ZeroSetSample> sampleZeroSet(int linesPerEdge,
                                           std::span<const uint32_t> leaves) const;

 private:
  struct Node {
    std::array<uint32_t, 8> child;  // kNoNode where absent
    uint32_t leaf = kNoNode;        // index into leaves_ for filled leaves
  };
  struct Traversal;

  bool intersectNode(uint32_t node, uint8_t level, const std::array<uint32_t, 3>& cell, double t0,
                     double t1, Traversal& state) const;
  bool intersectLeaf(uint32_t leaf, double t0, double t1, Traversal& state) const;
  std::optional<Vec3> bisectSignChange(Vec3 a, Vec3 b) const;
  FileHeader header_;
  std::optional<Region> region_;
  std::vector<Node> nodes_;  // node 0 is the root (level 0)
  std::vector<Leaf> leaves_;
  CornerValues corners_;
  std::vector<CornerSource> sources_;
  FlatMap<uint64_t, uint32_t> lightOverrides_;  // leaf << 3 | corner: into overrideValues_
  std::vector<std::array<float, 3>> overrideValues_;
};

}  // namespace iso
