// Distances between points and the zero set of an .iso surface, in world units.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <optional>
#include <span>
#include <vector>

#include "iso/format.h"
#include "iso/surface_model.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct DistanceStats {
  uint64_t samples = 0;      // points measured
  uint64_t unprojected = 0;  // points whose projection found no zero set (not in the statistics)
  double mean = 0.0, rms = 0.0, max = 0.0;
  std::vector<double> values;  // per projected point, when asked for
};

// Distance of each point (world coordinates) to the zero set, by projection onto it; `projected`,
// when given, receives each point's projection (frame units; none where it found no zero set).
DistanceStats pointsToZeroSet(const SurfaceModel& surface, const Frame& frame,
                              std::span<const glm::dvec3> points, bool keepValues = false,
                              std::vector<std::optional<Vec3>>* projected = nullptr);

// The same from a file, region by region (specs/pipeline.md §10): the points are grouped by cell
// of the coarsest level whose cells a surface meets hold about regionLeaves leaves (4^level cells
// for the file's leaves), and each group is measured against the chunks that meet its cell
// widened by 1/16 of it; a point whose projection leaves that box is measured again with the
// margin doubled, and so on. So about a region's leaves are decoded at once, and every distance
// is the one the whole model gives.
// A region's decoded surface takes about kDecodedLeafBytes a leaf at its peak (the model's nodes,
// leaves, corners and index as they grow, and a chunk's decoded layout while it is linked:
// measured on the 20M dragon).
inline constexpr uint64_t kRegionLeaves = 2000000;
inline constexpr uint64_t kDecodedLeafBytes = 600;
DistanceStats pointsToZeroSet(const Reader& reader, const Frame& frame,
                              std::span<const glm::dvec3> points, bool keepValues = false,
                              uint64_t regionLeaves = kRegionLeaves);

// Every step-th point, at most `limit` of them, spread over the whole cloud.
std::vector<glm::dvec3> samplePoints(const PointCloud& cloud, size_t limit);

// The point spacing: the median distance from each point to its nearest other point (exact
// duplicates skipped), as the conversion reports it.
double pointSpacing(const PointCloud& cloud);

}  // namespace iso
