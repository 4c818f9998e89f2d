// Synthetic scans of shapes with a known answer (`iso gen`).
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>

#include "pipeline/geom/shape.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct GenerateOptions {
  uint64_t count = 200000;    // points
  double noise = 0.0;         // standard deviation of displacement along the normal, in spacings
  double densityRatio = 1.0;  // densest / sparsest sampling density, varying smoothly along x
  glm::dvec3 offset{0.0};     // added to every position (e.g. UTM-like 500000,4900000,0)
  bool normals = true;        // write the true normals
  uint64_t seed = 1;
};

// The expected mean nearest-neighbour distance of `count` points spread uniformly over `area`
// (a Poisson process: 1 / (2 sqrt(density))). "Spacing" in GenerateOptions means this value.
double expectedSpacing(double area, uint64_t count);

// Sample `count` points of the shape: area-uniform (times the density variation), each displaced
// along its normal by Gaussian noise, offset, with unit normals unless options.normals is false.
// Deterministic for a given seed whatever the machine.
PointCloud generateScan(const Shape& shape, const GenerateOptions& options);

}  // namespace iso
