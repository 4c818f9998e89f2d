// In-memory point clouds and triangle meshes as readers produce them and generators make them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

namespace iso {

// Points in world coordinates. Positions are double so that large absolute coordinates (UTM,
// ECEF) keep millimetre detail. Optional attributes are either empty or one entry per point.
struct PointCloud {
  std::vector<glm::dvec3> positions;
  std::vector<glm::vec3> normals;  // as stored in the input (not necessarily unit length)
  std::vector<glm::vec3> colors;   // linear RGB in [0, 1] (inputs' sRGB is decoded on reading)
  // Further per-point scalars carried from the input (ReadOptions::keepExtras), by name.
  std::vector<std::string> extraNames;
  std::vector<double> extras;  // extraNames.size() values per point, point-major

  size_t size() const { return positions.size(); }
  bool hasNormals() const { return !normals.empty(); }
  bool hasColors() const { return !colors.empty(); }
  size_t extraCount() const { return extraNames.size(); }
  // Remove every point and attribute, extra names included.
  void clear() {
    positions.clear();
    normals.clear();
    colors.clear();
    extraNames.clear();
    extras.clear();
  }
};

// Append point i of `from` with its normal and color (extras are left out).
inline void appendPoint(PointCloud& to, const PointCloud& from, size_t i) {
  to.positions.push_back(from.positions[i]);
  if (from.hasNormals()) to.normals.push_back(from.normals[i]);
  if (from.hasColors()) to.colors.push_back(from.colors[i]);
}

// A triangle mesh in world coordinates (e.g. the ground truth of a scan).
struct TriangleMesh {
  std::vector<glm::dvec3> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;  // indices into vertices, counter-clockwise
};

}  // namespace iso
