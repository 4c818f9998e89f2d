// Points prepared to be drawn as they are (`iso view` of raw scans, viewer/image_view.h): no
// frame, no octree; each point's spacing and a normal.
#pragma once

#include <glm/vec3.hpp>
#include <vector>

#include "pipeline/io/point_cloud.h"

namespace iso {

struct ViewingPoints {
  std::vector<glm::vec3> positions;  // world minus the origin
  std::vector<glm::vec3> normals;    // unit (zero where unknown)
  std::vector<glm::vec3> colors;     // linear RGB, or empty
  std::vector<float> spacings;       // each point's: its third nearest neighbour, at most 8
                                     // times the median (a duplicate or a stray do not count)
  float spacing = 0.0f;              // the median of spacings
  bool normalsEstimated = false;     // the cloud had none: from 10 neighbours, unoriented
};

// The cloud's points (moved from it) relative to `origin`. A cloud of at most 10 points gets
// the spacing `fallbackSpacing` and no normals.
ViewingPoints prepareForViewing(PointCloud&& cloud, const glm::dvec3& origin,
                                float fallbackSpacing);

}  // namespace iso
