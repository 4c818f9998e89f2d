#include "measure.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

#include "knn.h"
#include "stages.h"

namespace iso {

DistanceStats pointsToZeroSet(const SurfaceModel& surface, const Frame& frame,
                              std::span<const glm::dvec3> points, bool keepValues) {
  std::vector<double> distance(points.size(), -1.0);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, points.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const glm::dvec3 p = toFrame(points[i], frame);
          if (const std::optional<Vec3> x = surface.project({p.x, p.y, p.z}))
            distance[i] = glm::length(glm::dvec3((*x)[0], (*x)[1], (*x)[2]) - p) * frame.size;
        }
      });
  DistanceStats stats;
  stats.samples = points.size();
  double sum = 0.0, squares = 0.0;
  for (double d : distance) {
    if (d < 0.0) {
      ++stats.unprojected;
      continue;
    }
    sum += d;
    squares += d * d;
    stats.max = std::max(stats.max, d);
    if (keepValues) stats.values.push_back(d);
  }
  const double n = double(stats.samples - stats.unprojected);
  if (n > 0) {
    stats.mean = sum / n;
    stats.rms = std::sqrt(squares / n);
  }
  return stats;
}

std::vector<glm::dvec3> samplePoints(const PointCloud& cloud, size_t limit) {
  const size_t n = cloud.size();
  const size_t step = std::max<size_t>(1, (n + limit - 1) / std::max<size_t>(limit, 1));
  std::vector<glm::dvec3> out;
  for (size_t i = 0; i < n; i += step) out.push_back(cloud.positions[i]);
  return out;
}

double meanNearestSpacing(const PointCloud& cloud) {
  if (cloud.size() < 2) return 0.0;
  const Frame frame = chooseFrame(cloud);
  PointSet points = makePointSet(cloud, frame);
  sortByKey(points);
  mergeDuplicates(points);
  if (points.size() < 2) return 0.0;
  const PointIndex tree(points.position);
  const Neighbors neighbors = findNeighbors(points, tree, 1);
  double sum = 0.0;
  for (float d : neighbors.distance) sum += d;
  return sum / double(points.size()) * frame.size;
}

}  // namespace iso
