// Triangle mesh as a shape: area-weighted sampling, and closest point and ray queries through a
// bounding volume hierarchy over the triangles of positive area.
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>
#include <string>

#include "iso/error.h"
#include "pipeline/geom/bvh.h"
#include "pipeline/geom/random.h"
#include "pipeline/geom/shape.h"
#include "pipeline/geom/triangle.h"

namespace iso {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
// Robust slab test (Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013): moving the exit distance
// outwards by 2γ₃ of itself makes the rounded test conservative.
constexpr double kGamma3 = 3.0 * 0x1.0p-53 / (1.0 - 3.0 * 0x1.0p-53);
constexpr double kWiden = 1.0 + 2.0 * kGamma3, kNarrow = 1.0 - 2.0 * kGamma3;

struct Triangle {
  glm::dvec3 a, b, c;
};

glm::dvec3 unitNormal(const Triangle& t) {
  const glm::dvec3 n = glm::cross(t.b - t.a, t.c - t.a);
  return n / std::sqrt(glm::dot(n, n));
}

double triangleArea(const Triangle& t) {
  const glm::dvec3 n = glm::cross(t.b - t.a, t.c - t.a);
  return 0.5 * std::sqrt(glm::dot(n, n));
}

bool isFinite(const glm::dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Squared distance from a point (in the hierarchy's frame) to a node's box; zero inside.
double boxDistance2(const BvhNode& n, const glm::dvec3& q) {
  double d2 = 0.0;
  for (int axis = 0; axis < 3; ++axis) {
    const double below = double(n.lower[axis]) - q[axis];
    const double above = q[axis] - double(n.upper[axis]);
    const double d = std::max({below, above, 0.0});
    d2 += d * d;
  }
  return d2;
}

// A ray in the hierarchy's frame for slab tests. Slab distances are taken near side first by the
// direction's sign, and the comparisons ignore NaN (0 × ∞ for a ray in a slab's plane), which then
// constrains nothing.
struct BoxRay {
  glm::dvec3 origin;
  glm::dvec3 inverse;
  std::array<bool, 3> negative;

  BoxRay(const glm::dvec3& o, const glm::dvec3& d) : origin(o), inverse(1.0 / d) {
    for (int i = 0; i < 3; ++i) negative[i] = std::signbit(d[i]);
  }

  // The parameter where the ray enters the node's box if it meets it within [tMin, tMax].
  bool enters(const BvhNode& n, double tMin, double tMax, double& tEnter) const {
    for (int axis = 0; axis < 3; ++axis) {
      const double lower = n.lower[axis], upper = n.upper[axis];
      const double near = ((negative[axis] ? upper : lower) - origin[axis]) * inverse[axis];
      double far = ((negative[axis] ? lower : upper) - origin[axis]) * inverse[axis];
      far *= far > 0.0 ? kWiden : kNarrow;
      if (near > tMin) tMin = near;
      if (far < tMax) tMax = far;
    }
    tEnter = tMin;
    return tMin <= tMax && tMin < kInfinity;
  }
};

// A node still to visit, with the bound (distance² or entry parameter) it had when it was pushed.
struct StackEntry {
  uint32_t node;
  double bound;
};

using Stack = std::array<StackEntry, Bvh::kMaxDepth>;

// Depth first over the hierarchy from the root: leaf(n) visits a leaf; next(n, stack, top) returns
// the child of an internal node to visit next, if any, having pushed the other one when it is
// worth a visit too; pruned(bound) tells when a pushed node is no longer worth one.
template <typename Leaf, typename Next, typename Pruned>
void depthFirst(const Bvh& bvh, const Leaf& leaf, const Next& next, const Pruned& pruned) {
  Stack stack;
  int top = 0;
  uint32_t node = 0;
  for (;;) {
    const BvhNode& n = bvh.node(node);
    if (n.isLeaf()) {
      leaf(n);
    } else if (const std::optional<uint32_t> child = next(n, stack, top)) {
      node = *child;
      continue;
    }
    while (top > 0 && pruned(stack[top - 1].bound)) --top;
    if (top == 0) break;
    node = stack[--top].node;
  }
}

// Start loading what visiting a node will read: its children's pair, or its leaf's triangles.
void prefetchVisit(const Bvh& bvh, const std::vector<Triangle>& triangles, const BvhNode& n) {
  if (n.isLeaf()) {
    const char* first = reinterpret_cast<const char*>(&triangles[n.first]);
    __builtin_prefetch(first);
    __builtin_prefetch(first + 64);
  } else {
    __builtin_prefetch(&bvh.pairs[n.first >> 1]);
  }
}

constexpr uint32_t kNoTriangle = 0xffffffffu;

// The best triangle so far of a closest-point query.
struct Nearest {
  double distance2 = kInfinity;
  glm::dvec3 point{0.0};
  uint32_t triangle = 0;
};

class MeshShape final : public Shape {
 public:
  explicit MeshShape(TriangleMesh mesh) : mesh_(std::move(mesh)) {
    validate();
    const std::vector<uint32_t> kept = weighTriangles();
    if (kept.empty()) throw UsageError("mesh: no triangle has a positive area");
    buildHierarchy(kept);
    isClosed_ = everyEdgeSharedByTwo();
  }

  std::string name() const override { return "mesh"; }
  double area() const override { return cumulativeArea_.back(); }
  bool isClosed() const override { return isClosed_; }
  glm::dvec3 boundsMin() const override { return lower_; }
  glm::dvec3 boundsMax() const override { return upper_; }

  // A triangle by area (binary search of the cumulative areas; zero-area triangles own an empty
  // interval and are never drawn), then a uniform point by the square-root parametrization (Osada
  // et al., "Shape Distributions", 2002, eq. 1).
  SurfacePoint sample(std::mt19937_64& rng) const override {
    const double target = uniform01(rng) * cumulativeArea_.back();
    const size_t index =
        std::min(size_t(std::upper_bound(cumulativeArea_.begin(), cumulativeArea_.end(), target) -
                        cumulativeArea_.begin()),
                 cumulativeArea_.size() - 1);
    const Triangle t = triangle(index);
    const double r = std::sqrt(uniform01(rng));
    const double s = uniform01(rng);
    return {(1.0 - r) * t.a + (r * (1.0 - s)) * t.b + (r * s) * t.c, unitNormal(t)};
  }

  ClosestPoint closest(const glm::dvec3& query) const override;
  std::optional<ClosestPoint> closestWithin(const glm::dvec3& query,
                                            double maxDistance) const override;
  std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                  double tMin, double tMax) const override;

 private:
  Triangle triangle(size_t index) const {
    const std::array<uint32_t, 3>& v = mesh_.triangles[index];
    return {mesh_.vertices[v[0]], mesh_.vertices[v[1]], mesh_.vertices[v[2]]};
  }

  void closestInLeaf(const glm::dvec3& query, uint32_t first, uint32_t count, Nearest& best) const;
  std::optional<uint32_t> nearerChild(const glm::dvec3& local, const BvhNode& n, double best2,
                                      Stack& stack, int& top) const;
  std::optional<uint32_t> enterChildren(const BoxRay& ray, const BvhNode& n, double tMin,
                                        double tMax, Stack& stack, int& top) const;
  void validate() const;
  std::vector<uint32_t> weighTriangles();
  void buildHierarchy(const std::vector<uint32_t>& kept);
  bool everyEdgeSharedByTwo() const;

  TriangleMesh mesh_;                   // as given: the sampling draws from it
  std::vector<double> cumulativeArea_;  // over mesh_.triangles
  Bvh bvh_;
  std::vector<Triangle> triangles_;  // the triangles of positive area in the hierarchy's leaf order
  glm::dvec3 lower_{0.0}, upper_{0.0};
  bool isClosed_ = false;
};

void MeshShape::validate() const {
  const size_t vertexCount = mesh_.vertices.size();
  if (mesh_.triangles.size() >= std::numeric_limits<uint32_t>::max())
    throw UsageError("mesh: too many triangles (at most 2^32 - 2)");
  for (size_t i = 0; i < mesh_.triangles.size(); ++i) {
    for (uint32_t v : mesh_.triangles[i]) {
      if (v >= vertexCount)
        throw UsageError("mesh: triangle " + std::to_string(i) + " uses vertex " +
                         std::to_string(v) + " of " + std::to_string(vertexCount));
      const glm::dvec3& p = mesh_.vertices[v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw UsageError("mesh: vertex " + std::to_string(v) + " is not finite");
    }
  }
}

// Fill the cumulative areas (a sequential sum, so the same on every run) and return the triangles
// of positive area, the only ones that queries can meet.
std::vector<uint32_t> MeshShape::weighTriangles() {
  const size_t count = mesh_.triangles.size();
  cumulativeArea_.resize(std::max<size_t>(count, 1), 0.0);
  tbb::parallel_for(size_t(0), count,
                    [&](size_t i) { cumulativeArea_[i] = triangleArea(triangle(i)); });
  std::vector<uint32_t> kept;
  double sum = 0.0;
  for (size_t i = 0; i < count; ++i) {
    if (cumulativeArea_[i] > 0.0) kept.push_back(uint32_t(i));
    sum += cumulativeArea_[i];
    cumulativeArea_[i] = sum;
  }
  return kept;
}

void MeshShape::buildHierarchy(const std::vector<uint32_t>& kept) {
  std::vector<Box> boxes(kept.size());
  tbb::parallel_for(size_t(0), kept.size(), [&](size_t i) {
    const Triangle t = triangle(kept[i]);
    boxes[i] = {glm::min(t.a, glm::min(t.b, t.c)), glm::max(t.a, glm::max(t.b, t.c))};
  });
  lower_ = glm::dvec3(kInfinity);
  upper_ = glm::dvec3(-kInfinity);
  for (const Box& b : boxes) {
    lower_ = glm::min(lower_, b.lower);
    upper_ = glm::max(upper_, b.upper);
  }
  bvh_ = buildBvh(boxes);
  triangles_.resize(kept.size());
  tbb::parallel_for(size_t(0), kept.size(),
                    [&](size_t i) { triangles_[i] = triangle(kept[bvh_.order[i]]); });
}

// Triangles with a repeated vertex index are points or segments and contribute no edges.
bool MeshShape::everyEdgeSharedByTwo() const {
  std::vector<uint64_t> edges;
  edges.reserve(3 * mesh_.triangles.size());
  for (const std::array<uint32_t, 3>& t : mesh_.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) continue;
    for (int i = 0; i < 3; ++i) {
      const uint64_t a = t[i], b = t[(i + 1) % 3];
      edges.push_back(std::min(a, b) << 32 | std::max(a, b));
    }
  }
  if (edges.empty()) return false;
  tbb::parallel_sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size(); i += 2)
    if (i + 1 >= edges.size() || edges[i] != edges[i + 1] ||
        (i + 2 < edges.size() && edges[i + 2] == edges[i]))
      return false;
  return true;
}

// Depth first, the nearer child first, pruning boxes no nearer than the best triangle so far.
// Prefetching the children's next reads hides part of the memory latency that bounds random queries
// on meshes larger than the caches. A query that is not finite has no closest point (NaN).
ClosestPoint MeshShape::closest(const glm::dvec3& query) const {
  if (!isFinite(query)) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    return {glm::dvec3(nan), glm::dvec3(nan), nan};
  }
  return *closestWithin(query, kInfinity);
}

// closest() with the search's bound starting at maxDistance: boxes farther are never opened.
std::optional<ClosestPoint> MeshShape::closestWithin(const glm::dvec3& query,
                                                     double maxDistance) const {
  if (!isFinite(query)) return std::nullopt;
  const glm::dvec3 local = query - bvh_.origin;
  Nearest best;
  // (a triangle exactly maxDistance away counts: the bound is a little above its square)
  best.distance2 = maxDistance < kInfinity ? maxDistance * maxDistance * (1.0 + 1e-12) : kInfinity;
  best.triangle = kNoTriangle;
  depthFirst(
      bvh_, [&](const BvhNode& n) { closestInLeaf(query, n.first, n.count, best); },
      [&](const BvhNode& n, Stack& stack, int& top) {
        return nearerChild(local, n, best.distance2, stack, top);
      },
      [&](double bound) { return bound >= best.distance2; });
  if (best.triangle == kNoTriangle) return std::nullopt;
  return ClosestPoint{best.point, unitNormal(triangles_[best.triangle]), std::sqrt(best.distance2)};
}

void MeshShape::closestInLeaf(const glm::dvec3& query, uint32_t first, uint32_t count,
                              Nearest& best) const {
  for (uint32_t i = first; i < first + count; ++i) {
    const Triangle& t = triangles_[i];
    const glm::dvec3 p = closestPointOnTriangle(query, t.a, t.b, t.c);
    const double d2 = glm::dot(query - p, query - p);
    if (d2 < best.distance2) best = {d2, p, i};
  }
}

// The child to visit next, if either is nearer than the best so far; the other one, if nearer too,
// is pushed. Both children's next reads are prefetched.
std::optional<uint32_t> MeshShape::nearerChild(const glm::dvec3& local, const BvhNode& n,
                                               double best2, Stack& stack, int& top) const {
  uint32_t nearChild = n.first, farChild = n.first + 1;
  double nearD2 = boxDistance2(bvh_.node(nearChild), local);
  double farD2 = boxDistance2(bvh_.node(farChild), local);
  if (farD2 < nearD2) {
    std::swap(nearChild, farChild);
    std::swap(nearD2, farD2);
  }
  if (!(nearD2 < best2)) return std::nullopt;
  prefetchVisit(bvh_, triangles_, bvh_.node(nearChild));
  if (farD2 < best2) {
    prefetchVisit(bvh_, triangles_, bvh_.node(farChild));
    stack[top++] = {farChild, farD2};
  }
  return nearChild;
}

// Depth first, the child the ray enters first visited first; boxes entered beyond the nearest hit
// so far are skipped.
std::optional<double> MeshShape::intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                           double tMin, double tMax) const {
  if (!isFinite(origin) || !isFinite(direction) || !(glm::dot(direction, direction) > 0.0) ||
      !(tMin < tMax))
    return std::nullopt;
  const ShearedRay ray(origin, direction);
  const BoxRay boxRay(origin - bvh_.origin, direction);
  std::optional<double> nearest;
  double limit = tMax, enter = 0.0;
  if (!boxRay.enters(bvh_.node(0), tMin, limit, enter)) return std::nullopt;
  depthFirst(
      bvh_,
      [&](const BvhNode& n) {
        for (uint32_t i = n.first; i < n.first + n.count; ++i) {
          const Triangle& t = triangles_[i];
          if (const std::optional<double> hit = intersectTriangle(ray, t.a, t.b, t.c, tMin, limit))
            nearest = limit = *hit;
        }
      },
      [&](const BvhNode& n, Stack& stack, int& top) {
        return enterChildren(boxRay, n, tMin, limit, stack, top);
      },
      [&](double bound) { return bound > limit; });
  return nearest;
}

// The child to visit next, if the ray enters either; the other one, if entered too, is pushed.
std::optional<uint32_t> MeshShape::enterChildren(const BoxRay& ray, const BvhNode& n, double tMin,
                                                 double tMax, Stack& stack, int& top) const {
  uint32_t nearChild = n.first, farChild = n.first + 1;
  double nearT = 0.0, farT = 0.0;
  bool isNearHit = ray.enters(bvh_.node(nearChild), tMin, tMax, nearT);
  bool isFarHit = ray.enters(bvh_.node(farChild), tMin, tMax, farT);
  if (isFarHit && (!isNearHit || farT < nearT)) {
    std::swap(nearChild, farChild);
    std::swap(nearT, farT);
    std::swap(isNearHit, isFarHit);
  }
  if (!isNearHit) return std::nullopt;
  if (isFarHit) stack[top++] = {farChild, farT};
  return nearChild;
}

}  // namespace

std::unique_ptr<Shape> makeMeshShape(TriangleMesh mesh) {
  return std::make_unique<MeshShape>(std::move(mesh));
}

}  // namespace iso
