// Points with a NaN or infinite coordinate, which every reader drops and counts.
#pragma once

#include <cmath>
#include <cstddef>
#include <glm/vec3.hpp>

#include "pipeline/io/point_cloud.h"

namespace iso::io {

inline bool isFinite(const glm::dvec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// Remove the points from `first` on whose position is not finite, keeping attributes (extras too)
// aligned; returns how many were removed. Nothing moves when all are finite (the common case).
size_t removeNonFinite(PointCloud& out, size_t first);

}  // namespace iso::io
