// Nearest-neighbour queries over points in frame units (a k-d tree from nanoflann).
//
// Threading: queries may run from many threads at once; building is single-threaded.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <memory>
#include <span>
#include <utility>
#include <vector>

namespace iso {

class KdTree {
 public:
  // The tree refers to the points, which must outlive it unchanged.
  explicit KdTree(std::span<const glm::vec3> points);
  ~KdTree();
  KdTree(const KdTree&) = delete;
  KdTree& operator=(const KdTree&) = delete;

  // The k nearest points (a query point in the set finds itself first), nearest first; returns how
  // many were found (fewer than k only when the set is smaller).
  size_t nearest(const glm::vec3& query, size_t k, uint32_t* indices,
                 float* squaredDistances) const;

  // All points within `radius`, unordered: (index, squared distance) pairs, replacing out's
  // content.
  void withinRadius(const glm::vec3& query, float radius,
                    std::vector<std::pair<uint32_t, float>>& out) const;

  size_t size() const { return points_.size(); }

 private:
  struct Index;
  std::span<const glm::vec3> points_;
  std::unique_ptr<Index> index_;
};

}  // namespace iso
