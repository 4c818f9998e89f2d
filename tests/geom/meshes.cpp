#include "tests/geom/meshes.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <utility>

namespace iso::test {
namespace {

// Shared midpoints keep the subdivided mesh closed.
class Subdivider {
 public:
  explicit Subdivider(TriangleMesh& mesh) : mesh_(mesh) {}

  void run() {
    std::vector<std::array<uint32_t, 3>> finer;
    finer.reserve(mesh_.triangles.size() * 4);
    for (const auto& [a, b, c] : mesh_.triangles) {
      const uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      finer.push_back({a, ab, ca});
      finer.push_back({b, bc, ab});
      finer.push_back({c, ca, bc});
      finer.push_back({ab, bc, ca});
    }
    mesh_.triangles = std::move(finer);
    midpoints_.clear();
  }

 private:
  uint32_t midpoint(uint32_t a, uint32_t b) {
    const std::pair<uint32_t, uint32_t> key(std::min(a, b), std::max(a, b));
    auto [it, isNew] = midpoints_.try_emplace(key, uint32_t(mesh_.vertices.size()));
    if (isNew) mesh_.vertices.push_back(glm::normalize(mesh_.vertices[a] + mesh_.vertices[b]));
    return it->second;
  }

  TriangleMesh& mesh_;
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoints_;
};

TriangleMesh unitIcosphere(int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  TriangleMesh mesh;
  for (const glm::dvec3& v :
       {glm::dvec3(-1, t, 0), glm::dvec3(1, t, 0), glm::dvec3(-1, -t, 0), glm::dvec3(1, -t, 0),
        glm::dvec3(0, -1, t), glm::dvec3(0, 1, t), glm::dvec3(0, -1, -t), glm::dvec3(0, 1, -t),
        glm::dvec3(t, 0, -1), glm::dvec3(t, 0, 1), glm::dvec3(-t, 0, -1), glm::dvec3(-t, 0, 1)})
    mesh.vertices.push_back(glm::normalize(v));
  mesh.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int i = 0; i < subdivisions; ++i) Subdivider(mesh).run();
  return mesh;
}

}  // namespace

TriangleMesh icosphere(int subdivisions, double radius, glm::dvec3 center) {
  TriangleMesh mesh = unitIcosphere(subdivisions);
  for (glm::dvec3& v : mesh.vertices) v = center + radius * v;
  return mesh;
}

TriangleMesh bumpySphere(int subdivisions, double amplitude) {
  TriangleMesh mesh = unitIcosphere(subdivisions);
  for (glm::dvec3& v : mesh.vertices)
    v *= 1.0 + amplitude * std::sin(5.0 * v.x) * std::sin(7.0 * v.y) * std::sin(3.0 * v.z + 1.0);
  return mesh;
}

TriangleMesh wavyGrid(int n) {
  TriangleMesh mesh;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      const double x = -1.0 + 2.0 * i / n, y = -1.0 + 2.0 * j / n;
      mesh.vertices.push_back({x, y, 0.2 * std::sin(3.0 * x) * std::cos(2.0 * y)});
    }
  }
  const auto index = [n](int i, int j) { return uint32_t(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh.triangles.push_back({index(i, j), index(i + 1, j), index(i + 1, j + 1)});
      mesh.triangles.push_back({index(i, j), index(i + 1, j + 1), index(i, j + 1)});
    }
  }
  return mesh;
}

}  // namespace iso::test
