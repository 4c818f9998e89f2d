#include "knn.h"

#include <nanoflann.hpp>

namespace iso {
namespace {

// nanoflann's dataset interface over the points, without copying them.
struct PointsAdaptor {
  std::span<const glm::vec3> points;
  size_t kdtree_get_point_count() const { return points.size(); }
  float kdtree_get_pt(size_t i, size_t dim) const { return points[i][int(dim)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointsAdaptor>,
                                                 PointsAdaptor, 3, uint32_t>;

}  // namespace

struct KdTree::Index {
  PointsAdaptor adaptor;
  Tree tree;
  explicit Index(std::span<const glm::vec3> points)
      : adaptor{points}, tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {}
};

KdTree::KdTree(std::span<const glm::vec3> points)
    : points_(points), index_(std::make_unique<Index>(points)) {}

KdTree::~KdTree() = default;

size_t KdTree::nearest(const glm::vec3& query, size_t k, uint32_t* indices,
                       float* squaredDistances) const {
  if (points_.empty() || k == 0) return 0;
  const float q[3] = {query.x, query.y, query.z};
  return index_->tree.knnSearch(q, k, indices, squaredDistances);
}

void KdTree::withinRadius(const glm::vec3& query, float radius,
                          std::vector<std::pair<uint32_t, float>>& out) const {
  out.clear();
  if (points_.empty()) return;
  const float q[3] = {query.x, query.y, query.z};
  index_->tree.radiusSearch(q, radius * radius, out, nanoflann::SearchParams(32, 0.0f, false));
}

}  // namespace iso
