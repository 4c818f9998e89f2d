// The adaptive octree (specs/pipeline.md, "Octree"). A node is subdivided while it is above the
// maximum depth and
//   - it holds more than leafPoints points and its own patch (the trilinear interpolation of its
//     8 corner distances) misses its points by more than the tolerance, or leaves surface where
//     there are no points (an open boundary, a hole: "coverage"), or
//   - it holds fewer points but is more than twice as wide as their largest radius, and its patch
//     leaves surface where there are no points, or
//   - its points have opposing normals (two sheets, a thin part): regardless of the point count,
//     because a trilinear patch has at most one zero crossing along an axis.
// Flat regions therefore stay coarse. Levels are built one at a time; the decisions of a level run
// in parallel.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

#include "pipeline/base/buffers.h"
#include "pipeline/base/options.h"
#include "pipeline/base/progress.h"
#include "pipeline/octree/field.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr int kCoverageLines = 4;     // zero-set samples per patch edge for coverage
constexpr double kNoiseFactor = 3.0;  // tolerance floor in RMS roughness
// A node with few points is still tested for coverage when it is wider than this many of its
// largest radius: the disks of a sparse or isolated point cover only part of it, and without the
// test its patch spans the whole cell (specs/pipeline.md measures 1, 2 and 3).
constexpr double kCoverageWidth = 2.0;

double cellSize(uint8_t level) { return std::ldexp(1.0, -level); }

glm::dvec3 cellOrigin(uint8_t level, uint64_t key) {
  const auto c = mortonDecode(key);
  return glm::dvec3(c[0], c[1], c[2]) * cellSize(level);
}

// Whether some point's normal opposes the points' mean normal (or the normals cancel).
bool hasOpposingNormals(const PointSet& points, const OctreeNode& node) {
  glm::vec3 mean(0.0f);
  for (uint32_t i = node.pointBegin; i < node.pointEnd; ++i)
    mean += points.normal[i] * points.weight[i];
  const float length = glm::length(mean);
  if (!(length > 1e-6f)) return node.pointCount() > 1;
  mean /= length;
  for (uint32_t i = node.pointBegin; i < node.pointEnd; ++i)
    if (glm::dot(points.normal[i], mean) < -0.5f) return true;
  return false;
}

// The patch a leaf would have in the file: its corners as quantized, so that the tolerance test
// also covers the quantization step (a large leaf's step can exceed the tolerance by itself).
Patch leafPatch(const OctreeNode& node, const CornerField& corners) {
  Patch patch(node.level, node.key);
  for (int c = 0; c < 8; ++c) {
    const float f = corners.value[corners.find(cornerPoint(node.level, node.key, c))].distance;
    patch.distance[size_t(c)] = roundTripDistance(f, node.level, kDistanceEncoding);
  }
  return patch;
}

// What happens to a node: the answer without a patch test, or the need for one, or why a tested
// node is subdivided.
enum class Verdict : uint8_t { Leaf, Subdivide, Test, Coverage, TooFar, Uncovered };

struct ToleranceScale {
  double tolerance, pointSpacing, medianRadius;
};

// maxEdge: the edge (frame units) above which nodes are subdivided without a test.
Verdict quickVerdict(const OctreeNode& node, const PointSet& points, const BuildOptions& options,
                     double maxEdge) {
  if (node.level >= options.maxDepth) return Verdict::Leaf;
  if (cellSize(node.level) > maxEdge) return Verdict::Subdivide;
  if (hasOpposingNormals(points, node)) return Verdict::Subdivide;
  if (node.pointCount() <= options.leafPoints)
    return cellSize(node.level) > kCoverageWidth * node.maxRadius ? Verdict::Coverage
                                                                   : Verdict::Leaf;
  if (node.pointCount() > options.maxTestedPoints) return Verdict::Subdivide;
  return Verdict::Test;
}

// Evaluate the corners of the nodes to be tested that the field does not hold yet.
void evaluateTestedCorners(const Octree& tree, const std::vector<uint32_t>& frontier,
                           const std::vector<Verdict>& verdict, const SdfEvaluator& sdf,
                           CornerField& corners) {
  std::vector<uint32_t> missing;
  for (size_t i = 0; i < frontier.size(); ++i) {
    if (verdict[i] != Verdict::Test && verdict[i] != Verdict::Coverage) continue;
    const OctreeNode& node = tree.nodes[frontier[i]];
    for (int c = 0; c < kCorners; ++c) {
      const auto [entry, added] = corners.insert(gridKey(cornerPoint(node.level, node.key, c)));
      if (added) missing.push_back(entry);
    }
  }
  evaluateCorners(corners, missing, sdf);
}

// Whether every zero crossing of the patch along a grid of lines lies within the radius of
// influence of its nearest point: surface only where points are. The grid's lines run through
// the middles of its cells and along the node's faces: where a flat patch holding points runs on
// past the end of an open surface, it is farthest from them at the node's faces (a 40k-point
// square's level-2 leaves reached 17 spacings past its rim between the middle lines).
bool isCovered(const Patch& patch, const SdfEvaluator& sdf, const PointSet& points,
               const OctreeNode& node) {
  glm::vec3 mean(0.0f);
  for (uint32_t i = node.pointBegin; i < node.pointEnd; ++i) mean += points.normal[i];
  const glm::vec3 a = glm::abs(mean);
  const int axis = a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const auto at = [](int i) {  // i = -1 .. kCoverageLines: the faces, and the middles between
    return i < 0 ? 0.0 : (i == kCoverageLines ? 1.0 : (i + 0.5) / kCoverageLines);
  };
  for (int i = -1; i <= kCoverageLines; ++i)
    for (int j = -1; j <= kCoverageLines; ++j) {
      glm::dvec3 lo = patch.origin, hi = patch.origin;
      lo[u] = hi[u] = patch.origin[u] + at(i) * patch.size;
      lo[v] = hi[v] = patch.origin[v] + at(j) * patch.size;
      hi[axis] += patch.size;
      const double f0 = patch.value(lo, nullptr), f1 = patch.value(hi, nullptr);
      // A zero at an end is a crossing too: a plane of points on a face of the node's grid
      // has its zero set there, and no sign changes along the lines.
      if (f0 != 0.0 && f1 != 0.0 && (f0 < 0.0) == (f1 < 0.0)) continue;
      glm::dvec3 x = lo;
      if (f0 != 0.0) x[axis] += patch.size * f0 / (f0 - f1);
      float distance = 0.0f;
      const uint32_t nearest = sdf.nearest(x, distance);
      if (distance > points.radius[nearest]) return false;
    }
  return true;
}

// The tolerance of a node in frame units: the option's, in units of the local point spacing (the
// spacing scaled by the points' radii against the median radius: sparse parts cannot hold
// detail finer than their sampling), but never below 3 times the points' roughness (RMS), so
// that noise is not mistaken for shape that needs smaller leaves.
double nodeTolerance(const OctreeNode& node, const PointSet& points, const ToleranceScale& scale) {
  double squares = 0.0, radii = 0.0;
  for (uint32_t i = node.pointBegin; i < node.pointEnd; ++i) {
    squares += double(points.roughness[i]) * points.roughness[i];
    radii += points.radius[i];
  }
  const double n = std::max<uint32_t>(node.pointCount(), 1);
  const double localSpacing = scale.pointSpacing * (radii / n) / scale.medianRadius;
  return std::max(scale.tolerance * localSpacing, kNoiseFactor * std::sqrt(squares / n));
}

Verdict patchTest(const OctreeNode& node, const PointSet& points, const SdfEvaluator& sdf,
                  const CornerField& corners, const ToleranceScale& tolerance) {
  const Patch patch = leafPatch(node, corners);
  if (patch.maxPointDistance(points, node.pointBegin, node.pointEnd) >
      nodeTolerance(node, points, tolerance))
    return Verdict::TooFar;
  return isCovered(patch, sdf, points, node) ? Verdict::Leaf : Verdict::Uncovered;
}

float maxRadiusOf(const PointSet& points, uint32_t begin, uint32_t end) {
  float r = 0.0f;
  for (uint32_t i = begin; i < end; ++i) r = std::max(r, points.radius[i]);
  return r;
}

}  // namespace

Patch::Patch(uint8_t level, uint64_t key) : origin(cellOrigin(level, key)), size(cellSize(level)) {}

double Patch::value(const glm::dvec3& p, glm::dvec3* gradient) const {
  const std::array<double, 3> u = {std::clamp((p.x - origin.x) / size, 0.0, 1.0),
                                   std::clamp((p.y - origin.y) / size, 0.0, 1.0),
                                   std::clamp((p.z - origin.z) / size, 0.0, 1.0)};
  std::array<double, 3> g{};
  const double f = trilinear(distance, u, gradient ? &g : nullptr);
  if (gradient) *gradient = glm::dvec3(g[0], g[1], g[2]) / size;
  return f;
}

double Patch::maxPointDistance(const PointSet& points, uint32_t begin, uint32_t end) const {
  double worst = 0.0;
  for (uint32_t i = begin; i < end; ++i) {
    if ((i - begin) % 65536 == 0) spillPause();  // (a coarse node's points: up to all of them)
    glm::dvec3 gradient;
    const double f = value(glm::dvec3(points.position[i]), &gradient);
    const double g = glm::length(gradient);
    worst =
        std::max(worst, g > 1e-12 ? std::abs(f) / g : size);  // a flat patch: as far as its cell
  }
  return worst;
}

uint32_t Octree::find(uint8_t level, uint64_t key) const {
  uint32_t node = 0;
  for (int l = 0; l < level; ++l) {
    if (nodes[node].kind != NodeKind::Internal) return node;
    node = nodes[node].firstChild + uint32_t((key >> (3 * (level - 1 - l))) & 7);
  }
  return node;
}

void Octree::split(uint32_t id, const PointSet& points) {
  const OctreeNode parent = nodes[id];
  const uint32_t first = uint32_t(nodes.size());
  const int shift = 3 * (kMaxLevel - parent.level - 1);
  uint32_t begin = parent.pointBegin;
  for (uint64_t o = 0; o < 8; ++o) {
    OctreeNode child;
    child.key = parent.key << 3 | o;
    child.level = uint8_t(parent.level + 1);
    const auto end =
        std::partition_point(points.key.begin() + begin, points.key.begin() + parent.pointEnd,
                             [&](uint64_t k) { return (k >> shift) <= child.key; });
    child.pointBegin = begin;
    child.pointEnd = uint32_t(end - points.key.begin());
    child.kind = child.pointCount() > 0 ? NodeKind::Leaf : NodeKind::Empty;
    child.maxRadius = maxRadiusOf(points, child.pointBegin, child.pointEnd);
    begin = child.pointEnd;
    nodes.push_back(child);
  }
  nodes[id].kind = NodeKind::Internal;
  nodes[id].firstChild = first;
}

uint32_t Octree::materialize(uint8_t level, uint64_t key, const PointSet& points) {
  for (;;) {
    const uint32_t node = find(level, key);
    if (nodes[node].level == level || nodes[node].kind != NodeKind::Empty) return node;
    split(node, points);  // an empty node: its children are empty too
  }
}

void Octree::updateMaxRadius(const PointSet& points) {
  for (size_t i = nodes.size(); i-- > 0;) {
    OctreeNode& node = nodes[i];
    if (node.kind == NodeKind::Internal) {
      node.maxRadius = 0.0f;
      for (uint32_t c = 0; c < 8; ++c)
        node.maxRadius = std::max(node.maxRadius, nodes[node.firstChild + c].maxRadius);
    } else {
      node.maxRadius = maxRadiusOf(points, node.pointBegin, node.pointEnd);
    }
  }
}

bool Octree::anyPointNear(const glm::dvec3& lo, const glm::dvec3& hi, const PointSet& points,
                          const std::function<bool(uint32_t)>& test) const {
  const auto boxDistance = [&](const glm::dvec3& a, const glm::dvec3& b) {
    const glm::dvec3 d = glm::max(glm::max(lo - b, a - hi), glm::dvec3(0.0));
    return glm::length(d);
  };
  // Every point whose disk may touch the box lies within the largest radius of it: the search
  // starts at the deepest internal node whose cell holds the box grown by that much (a point
  // exactly on a cell's middle belongs to the upper child, as its key says).
  const double reach = double(nodes[0].maxRadius) * (1.0 + 1e-9) + 1e-12;
  const glm::dvec3 grownLo = lo - reach, grownHi = hi + reach;
  uint32_t start = 0;
  for (;;) {
    const OctreeNode& node = nodes[start];
    if (node.kind != NodeKind::Internal) break;
    const glm::dvec3 middle = cellOrigin(node.level, node.key) + 0.5 * cellSize(node.level);
    uint32_t octant = 0;
    bool inOne = true;
    for (int a = 0; a < 3 && inOne; ++a) {
      if (grownLo[a] >= middle[a])
        octant |= 1u << a;
      else
        inOne = grownHi[a] < middle[a];
    }
    if (!inOne) break;
    start = node.firstChild + octant;
  }
  // Depth first: at most 7 waiting siblings per level besides the path.
  std::array<uint32_t, 8 * (kMaxLevel + 2)> stack;
  size_t top = 0;
  stack[top++] = start;
  while (top > 0) {
    const OctreeNode& node = nodes[stack[--top]];
    if (node.pointCount() == 0) continue;
    const glm::dvec3 origin = cellOrigin(node.level, node.key);
    if (boxDistance(origin, origin + cellSize(node.level)) > node.maxRadius) continue;
    if (node.kind == NodeKind::Internal) {
      for (uint32_t c = 8; c-- > 0;) stack[top++] = node.firstChild + c;
      continue;
    }
    for (uint32_t i = node.pointBegin; i < node.pointEnd; ++i) {
      const glm::dvec3 p(points.position[i]);
      if (boxDistance(p, p) <= points.radius[i] && test(i)) return true;
    }
  }
  return false;
}

Octree buildOctree(const PointSet& points, const SdfEvaluator& sdf, const BuildOptions& options,
                   const RadiusStats& radii, CornerField& corners, OctreeStats* statsOut) {
  Octree tree;
  OctreeNode root;
  root.pointEnd = uint32_t(points.size());
  root.kind = root.pointCount() > 0 ? NodeKind::Leaf : NodeKind::Empty;
  tree.nodes.push_back(root);
  const ToleranceScale tolerance{options.tolerance, radii.spacing,
                                 std::max(radii.medianRadius, 1e-12)};
  // Tested nodes are at most this wide, so that no test reads points much farther away.
  const double maxEdge = options.maxTestedEdge * radii.spacing;
  std::vector<uint32_t> frontier = {0};
  OctreeStats stats;
  while (!frontier.empty()) {  // one level at a time
    std::vector<Verdict> verdict(frontier.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, frontier.size(), 64),
                      [&](const tbb::blocked_range<size_t>& r) {
                        spillPause();
                        for (size_t i = r.begin(); i < r.end(); ++i)
                          verdict[i] =
                              quickVerdict(tree.nodes[frontier[i]], points, options, maxEdge);
                      });
    evaluateTestedCorners(tree, frontier, verdict, sdf, corners);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, frontier.size(), 16),
                      [&](const tbb::blocked_range<size_t>& r) {
                        spillPause();
                        for (size_t i = r.begin(); i < r.end(); ++i) {
                          if (verdict[i] == Verdict::Coverage) {
                            const OctreeNode& node = tree.nodes[frontier[i]];
                            verdict[i] = isCovered(leafPatch(node, corners), sdf, points, node)
                                             ? Verdict::Leaf
                                             : Verdict::Uncovered;
                            continue;
                          }
                          if (verdict[i] != Verdict::Test) continue;
                          verdict[i] =
                              patchTest(tree.nodes[frontier[i]], points, sdf, corners, tolerance);
                        }
                      });
    std::vector<uint32_t> next;
    for (size_t i = 0; i < frontier.size(); ++i) {
      const OctreeNode& node = tree.nodes[frontier[i]];
      stats.tooFar += verdict[i] == Verdict::TooFar;
      stats.uncovered += verdict[i] == Verdict::Uncovered;
      if (verdict[i] == Verdict::Leaf) continue;
      if (verdict[i] == Verdict::TooFar || verdict[i] == Verdict::Uncovered) ++stats.testedPatches;
      if (verdict[i] == Verdict::Subdivide && node.pointCount() <= options.leafPoints)
        ++stats.thinSplits;
      tree.split(frontier[i], points);
      const uint32_t first = tree.nodes[frontier[i]].firstChild;
      for (uint32_t c = 0; c < 8; ++c)
        if (tree.nodes[first + c].kind == NodeKind::Leaf) next.push_back(first + c);
    }
    frontier.swap(next);
  }
  tree.updateMaxRadius(points);
  if (statsOut) *statsOut = stats;
  return tree;
}

}  // namespace iso
