// Point clouds with analytic shapes for the image-space renderer's tests (CPU and GPU).
#pragma once

#include <cmath>
#include <glm/glm.hpp>
#include <numbers>
#include <random>

#include "tracer/point_image.h"

namespace iso::viewer {

using glm::vec3;

// n points spread evenly over a sphere (a Fibonacci lattice), normals outward.
inline ImageObject sphere(vec3 center, float radius, size_t n) {
  ImageObject o;
  const float golden = std::numbers::pi_v<float> * (3.0f - std::sqrt(5.0f));
  for (size_t i = 0; i < n; ++i) {
    const float y = 1.0f - 2.0f * (float(i) + 0.5f) / float(n);
    const float r = std::sqrt(1.0f - y * y);
    const vec3 d(r * std::cos(golden * float(i)), y, r * std::sin(golden * float(i)));
    o.positions.push_back(center + radius * d);
    o.normals.push_back(d);
  }
  o.spacing = radius * std::sqrt(4.0f * std::numbers::pi_v<float> / float(n));
  return o;
}

// A square [-half, half]² of the plane through `center` across `normal` (x/y or x/z), points on a
// jittered grid of this spacing.
inline ImageObject sheet(vec3 center, vec3 u, vec3 v, float half, float spacing, uint32_t seed) {
  ImageObject o;
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> jitter(-0.3f, 0.3f);
  const vec3 normal = glm::normalize(glm::cross(u, v));
  const int steps = int(std::floor(2.0f * half / spacing));
  for (int j = 0; j <= steps; ++j)
    for (int i = 0; i <= steps; ++i) {
      const float a = -half + spacing * (float(i) + (i > 0 && i < steps ? jitter(random) : 0.0f));
      const float b = -half + spacing * (float(j) + (j > 0 && j < steps ? jitter(random) : 0.0f));
      o.positions.push_back(center + a * u + b * v);
      o.normals.push_back(normal);
    }
  o.spacing = spacing;
  return o;
}

}  // namespace iso::viewer
