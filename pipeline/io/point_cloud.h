// In-memory point clouds and triangle meshes as readers produce them and generators make them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <vector>

namespace iso {

// Points in world coordinates. Positions are double so that large absolute coordinates (UTM,
// ECEF) keep millimetre detail. Optional attributes are either empty or one entry per point.
struct PointCloud {
  std::vector<glm::dvec3> positions;
  std::vector<glm::vec3> normals;  // as stored in the input (not necessarily unit length)
  std::vector<glm::vec3> colors;   // linear RGB in [0, 1] (inputs' sRGB is decoded on reading)

  size_t size() const { return positions.size(); }
  bool hasNormals() const { return !normals.empty(); }
  bool hasColors() const { return !colors.empty(); }
  void clear() {
    positions.clear();
    normals.clear();
    colors.clear();
  }
};

// A triangle mesh in world coordinates (e.g. the ground truth of a scan).
struct TriangleMesh {
  std::vector<glm::dvec3> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;  // indices into vertices, counter-clockwise
};

}  // namespace iso
