// Raw scans for `iso view --draw image` (view_points.h).
#include "tools/iso/view_points.h"

#include <chrono>

#include "pipeline/io/readers.h"
#include "pipeline/points/viewing.h"

namespace iso::cli {

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
  const float fallback = std::max(float(glm::length(hi - lo)) * 0.01f, 1e-6f);
  for (PointCloud& cloud : clouds) {
    ViewingPoints v = prepareForViewing(std::move(cloud), in.origin, fallback);
    viewer::ImageObject o;
    o.positions = std::move(v.positions);
    o.normals = std::move(v.normals);
    o.colors = std::move(v.colors);
    o.spacings = std::move(v.spacings);
    o.spacing = v.spacing;
    o.orientedNormals = !v.normalsEstimated;
    in.normalsEstimated |= v.normalsEstimated;
    in.objects.push_back(std::move(o));
  }
  in.loadSeconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return in;
}

}  // namespace iso::cli
