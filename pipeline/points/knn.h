// Nearest-neighbour queries over a fixed set of points: an octree of small buckets over the
// points in Morton order, with tight bounding boxes (specs/pipeline.md, "Neighbour queries").
//
// Points in [0, 1)^3 (frame units) that are already in Morton order at kMaxLevel are indexed
// without a copy of their order; other points are sorted into Morton order of their bounding cube.
// Every query is exact and deterministic: ties between equal distances go to the point earlier
// in the index's Morton order, whatever order the search meets them in.
//
// Threading: queries may run from many threads at once; building runs on the calling thread's
// task arena.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>

#include <span>
#include <utility>
#include <vector>

#include "iso/flat_map.h"
#include "pipeline/base/buffers.h"

namespace iso {

class PointIndex {
 public:
  // The index copies the positions; the span need not outlive it.
  explicit PointIndex(std::span<const glm::vec3> points);

  // The k nearest points (a query point in the set finds itself first), nearest first; returns how
  // many were found (fewer than k only when the set is smaller).
  size_t nearest(const glm::vec3& query, size_t k, uint32_t* indices,
                 float* squaredDistances) const;

  // All points within `radius` (inclusive), in the index's Morton order: (index, squared distance)
  // pairs, replacing out's content.
  void withinRadius(const glm::vec3& query, float radius,
                    std::vector<std::pair<uint32_t, float>>& out) const;

  // For every indexed point i, its k nearest other points, nearest first: indices[i·k + j] and
  // their distances (not squared). Requires k < size().
  void allNearest(size_t k, uint32_t* indices, float* distances) const;

  size_t size() const { return x_.size(); }

 private:
  struct Node {
    float lo[3];
    uint32_t begin;  // sorted points [begin, end)
    float hi[3];
    uint32_t end;
    uint32_t firstChild;  // children are contiguous; none for a bucket
    uint32_t childCount;
  };
  struct Search;
  struct Children;
  static Children split(std::span<const uint64_t> keys, const Node& node, uint8_t level);

  void build(std::span<const uint64_t> keys);
  uint64_t keyOf(const glm::vec3& p) const;
  // The deepest node that is a whole octree cell holding every point within pad of the box.
  uint32_t startNode(const glm::vec3& lo, const glm::vec3& hi, float pad) const;
  static uint64_t cellCode(uint8_t level, uint64_t prefix) {
    return uint64_t(1) << (3 * level) | prefix;
  }
  uint32_t original(uint32_t sorted) const { return order_.empty() ? sorted : order_[sorted]; }
  // The buckets within sqrt(radius2) of the box [lo, hi], in point order.
  void collectLeaves(const float lo[3], const float hi[3], float radius2,
                     std::vector<uint32_t>& out) const;

  UninitializedSpillVector<float> x_, y_, z_;  // positions in sorted order
  std::vector<uint32_t> order_;   // sorted → original index; empty when the input was sorted
  UninitializedSpillVector<Node> nodes_;  // nodes_[0] is the root
  UninitializedSpillVector<uint32_t> leaves_;  // the buckets, in point order
  UninitializedSpillVector<uint64_t> leafKey_;  // Morton key of each bucket's first point
  // cellCode → node, for nodes that are whole cells
  FlatMap<uint64_t, uint32_t, SpillAllocator<std::pair<uint64_t, uint32_t>>> cells_;
  glm::dvec3 origin_{0.0};         // the cube of the keys: origin and cells per unit
  double cellsPerUnit_ = 1.0;
};

}  // namespace iso
