// Points prepared to be drawn as they are (viewing.h).
#include "pipeline/points/viewing.h"

#include <algorithm>
#include <glm/geometric.hpp>

#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr int kNeighbours = 10;  // a point's spacing and normal come from these

}  // namespace

ViewingPoints prepareForViewing(PointCloud&& cloud, const glm::dvec3& origin,
                                float fallbackSpacing) {
  ViewingPoints v;
  const size_t n = cloud.size();
  PointSet set;
  set.position.resize(n);
  for (size_t i = 0; i < n; ++i) set.position[i] = glm::vec3(cloud.positions[i] - origin);
  v.positions.assign(set.position.begin(), set.position.end());
  v.colors = std::move(cloud.colors);
  if (n <= size_t(kNeighbours)) {
    v.spacing = fallbackSpacing;
    return v;
  }
  const PointIndex index(v.positions);
  const Neighbors neighbours = findNeighbors(set, index, kNeighbours);
  v.spacings.resize(n);
  for (size_t i = 0; i < n; ++i)
    v.spacings[i] = std::max(neighbours.distance[i * kNeighbours + 2], 1e-9f);
  std::vector<float> sorted = v.spacings;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  v.spacing = std::max(sorted[n / 2], 1e-9f);
  for (float& s : v.spacings) s = std::min(s, 8.0f * v.spacing);
  if (cloud.hasNormals()) {
    set.normal.resize(n);
    for (size_t i = 0; i < n; ++i) {
      const float length = glm::length(cloud.normals[i]);
      set.normal[i] = length > 0.0f ? cloud.normals[i] / length : glm::vec3(0.0f);
    }
  } else {
    v.normalsEstimated = true;
  }
  estimateNormals(set, neighbours);  // where there is none
  v.normals.assign(set.normal.begin(), set.normal.end());
  return v;
}

}  // namespace iso
