// Raw scans for `iso view --draw image` (view_points.h).
#include "tools/iso/view_points.h"

#include <algorithm>
#include <chrono>

#include "pipeline/io/readers.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso::cli {
namespace {

// Neighbours a point's spacing and normal come from.
constexpr int kNeighbours = 10;

float medianOf(std::vector<float> v) {
  if (v.empty()) return 0.0f;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

viewer::ImageInputs loadImageInputs(const std::vector<std::filesystem::path>& files) {
  const auto start = std::chrono::steady_clock::now();
  viewer::ImageInputs in;
  std::vector<PointCloud> clouds;
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (const auto& file : files) {
    const auto reader = openPointFile(file);
    const std::string format = reader->info().format;
    if (format.rfind("las", 0) == 0 || format.rfind("laz", 0) == 0 || format.rfind("e57", 0) == 0)
      in.up = {0, 0, 1};  // LiDAR: z up
    PointCloud cloud;
    while (reader->read(cloud, size_t(1) << 20) > 0) {
    }
    for (const glm::dvec3& p : cloud.positions) {
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    in.names.push_back(file.string());
    clouds.push_back(std::move(cloud));
  }
  if (lo.x > hi.x) lo = hi = glm::dvec3(0.0);
  in.bounds = {lo, hi};
  in.origin = 0.5 * (lo + hi);
  for (PointCloud& cloud : clouds) {
    viewer::ImageObject o;
    const size_t n = cloud.size();
    PointSet set;
    set.position.resize(n);
    for (size_t i = 0; i < n; ++i) set.position[i] = glm::vec3(cloud.positions[i] - in.origin);
    o.positions.assign(set.position.begin(), set.position.end());
    if (cloud.hasColors()) o.colors = std::move(cloud.colors);
    if (n > size_t(kNeighbours)) {
      const PointIndex index(o.positions);
      const Neighbors neighbours = findNeighbors(set, index, kNeighbours);
      // Each point's spacing: its third nearest neighbour (a duplicate or two do not shrink it).
      o.spacings.resize(n);
      for (size_t i = 0; i < n; ++i)
        o.spacings[i] = std::max(neighbours.distance[i * kNeighbours + 2], 1e-9f);
      o.spacing = std::max(medianOf(o.spacings), 1e-9f);
      for (float& s : o.spacings) s = std::min(s, 8.0f * o.spacing);  // strays do not spread
      if (cloud.hasNormals()) {
        set.normal.resize(n);
        for (size_t i = 0; i < n; ++i) {
          const float length = glm::length(cloud.normals[i]);
          set.normal[i] = length > 0.0f ? cloud.normals[i] / length : glm::vec3(0.0f);
        }
      } else {
        in.normalsEstimated = true;
        o.orientedNormals = false;
      }
      estimateNormals(set, neighbours);  // fills the zero ones
      o.normals.assign(set.normal.begin(), set.normal.end());
    } else {
      o.spacing = std::max(float(glm::length(hi - lo)) * 0.01f, 1e-6f);
    }
    in.objects.push_back(std::move(o));
  }
  in.loadSeconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return in;
}

}  // namespace iso::cli
