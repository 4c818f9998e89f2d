// One-to-one matching of two point sets within a tolerance, with their colors and normals: how
// the tests check kept points against their input without the writer's own arithmetic.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <vector>

#include "pipeline/io/color.h"
#include "pipeline/io/point_cloud.h"

namespace iso::test {

// Match every input point to a distinct kept point within `tolerance` (world units), by a grid of
// cells `tolerance` wide: a one-to-one matching of the two point sets, with sRGB 8-bit colors
// within `colorCodes` and unit normals within 1e-4 too. Where the input has no normal (none at
// all, or a zero one), a conversion keeps its estimated one: any unit normal (or none) matches.
inline void expectSamePoints(const PointCloud& input, const PointCloud& kept, double tolerance,
                             int colorCodes = 0) {
  ASSERT_EQ(kept.size(), input.size());
  ASSERT_EQ(kept.hasColors(), input.hasColors());
  if (input.hasNormals()) {
    ASSERT_TRUE(kept.hasNormals());
  }
  const auto cellOf = [&](const glm::dvec3& p) {
    return std::array<int64_t, 3>{int64_t(std::floor(p.x / tolerance)),
                                  int64_t(std::floor(p.y / tolerance)),
                                  int64_t(std::floor(p.z / tolerance))};
  };
  std::map<std::array<int64_t, 3>, std::vector<uint32_t>> grid;
  for (uint32_t i = 0; i < kept.size(); ++i) grid[cellOf(kept.positions[i])].push_back(i);
  std::vector<uint8_t> used(kept.size(), 0);
  size_t unmatched = 0, wrongAttributes = 0;
  for (size_t i = 0; i < input.size(); ++i) {
    const std::array<int64_t, 3> c = cellOf(input.positions[i]);
    bool found = false;
    for (int64_t dx = -1; dx <= 1 && !found; ++dx)
      for (int64_t dy = -1; dy <= 1 && !found; ++dy)
        for (int64_t dz = -1; dz <= 1 && !found; ++dz) {
          const auto it = grid.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == grid.end()) continue;
          for (const uint32_t j : it->second) {
            if (used[j] || glm::length(kept.positions[j] - input.positions[i]) > tolerance)
              continue;
            // Duplicated positions may carry different attributes: match those too.
            if (input.hasColors()) {
              bool same = true;
              for (int a = 0; a < 3; ++a)
                same = same && std::abs(int(linearToSrgb8(kept.colors[j][a])) -
                                        int(linearToSrgb8(input.colors[i][a]))) <= colorCodes;
              if (!same) continue;
            }
            if (input.hasNormals()) {
              const float length = glm::length(input.normals[i]);
              const glm::vec3 unit = length > 0.0f ? input.normals[i] / length : glm::vec3(0.0f);
              const float keptLength = glm::length(kept.normals[j]);
              const bool estimated =
                  length == 0.0f && (keptLength == 0.0f || std::abs(keptLength - 1.0f) < 1e-3f);
              if (!estimated && glm::length(kept.normals[j] - unit) > 1e-4f) {
                ++wrongAttributes;
                continue;
              }
            }
            used[j] = 1;
            found = true;
            break;
          }
        }
    unmatched += found ? 0 : 1;
  }
  EXPECT_EQ(unmatched, 0u);
  EXPECT_EQ(wrongAttributes, 0u);
}

}  // namespace iso::test
