// Mesh simplification for the exports' levels of detail (pipeline/analysis/export.h): edge
// collapses by meshoptimizer, each result measured against the mesh and redone until it is
// within the error asked for.
#include <meshoptimizer.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>
#include <memory>
#include <vector>

#include "pipeline/analysis/export.h"
#include "pipeline/geom/shape.h"

namespace iso {

namespace {

constexpr int kSimplifyAttempts = 6;  // measured results before the mesh is kept whole
constexpr double kReach = 4.0;        // how far past maxError a failed result is measured

// Keep the vertices `remap` maps (~0: dropped), in their new order.
template <class T>
void remapColumn(std::vector<T>& column, const std::vector<uint32_t>& remap, size_t kept) {
  if (column.empty()) return;
  std::vector<T> out(kept);
  for (size_t v = 0; v < remap.size(); ++v)
    if (remap[v] != ~0u) out[remap[v]] = column[v];
  column.swap(out);
}

// Renumber the vertices in the order the indices first use them, dropping unused ones.
void compactMesh(TriangleMesh& mesh, MeshAttributes& attributes, std::vector<uint32_t>& indices) {
  std::vector<uint32_t> remap(mesh.vertices.size());
  const size_t kept = meshopt_optimizeVertexFetchRemap(remap.data(), indices.data(), indices.size(),
                                                       mesh.vertices.size());
  meshopt_remapIndexBuffer(indices.data(), indices.data(), indices.size(), remap.data());
  remapColumn(mesh.vertices, remap, kept);
  remapColumn(attributes.normals, remap, kept);
  remapColumn(attributes.colors, remap, kept);
  mesh.triangles.resize(indices.size() / 3);
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    mesh.triangles[t] = {indices[3 * t], indices[3 * t + 1], indices[3 * t + 2]};
}

std::vector<uint32_t> flatIndices(const TriangleMesh& mesh) {
  std::vector<uint32_t> indices(3 * mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    std::copy(mesh.triangles[t].begin(), mesh.triangles[t].end(), indices.begin() + 3 * t);
  return indices;
}

}  // namespace

void optimizeMeshOrder(TriangleMesh& mesh, MeshAttributes& attributes) {
  std::vector<uint32_t> indices = flatIndices(mesh);
  meshopt_optimizeVertexCache(indices.data(), indices.data(), indices.size(), mesh.vertices.size());
  compactMesh(mesh, attributes, indices);
}

namespace {

// The largest distance between two meshes, sampled both ways: from every vertex of `from` to
// `to`, and from a grid of points on each of `to`'s triangles to `from`; infinity as soon as one
// sample is farther than `limit` (the searches open no box beyond it).
double sampledDeviation(const Shape& from, const TriangleMesh& fromMesh, const TriangleMesh& to,
                        double limit) {
  const std::unique_ptr<Shape> toShape = makeMeshShape(to);
  std::atomic<double> worst{0.0};
  std::atomic<bool> beyond{false};
  const auto raise = [&](double d) {
    double seen = worst.load();
    while (d > seen && !worst.compare_exchange_weak(seen, d)) {
    }
  };
  // The distance from p to shape, or infinity (and stop) past the limit.
  const auto distance = [&](const Shape& shape, const glm::dvec3& p) {
    const std::optional<ClosestPoint> c = shape.closestWithin(p, limit);
    if (c) return c->distance;
    beyond = true;
    return std::numeric_limits<double>::infinity();
  };
  tbb::parallel_for(tbb::blocked_range<size_t>(0, fromMesh.vertices.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      double local = 0.0;
                      for (size_t v = r.begin(); v < r.end() && !beyond; ++v)
                        local = std::max(local, distance(*toShape, fromMesh.vertices[v]));
                      raise(local);
                    });
  constexpr int kGrid = 6;  // points a triangle edge is cut into
  tbb::parallel_for(tbb::blocked_range<size_t>(0, to.triangles.size(), 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      double local = 0.0;
                      for (size_t t = r.begin(); t < r.end() && !beyond; ++t) {
                        const auto& tri = to.triangles[t];
                        for (int i = 0; i <= kGrid; ++i)
                          for (int j = 0; i + j <= kGrid; ++j) {
                            const glm::dvec3 p =
                                (double(i) * to.vertices[tri[0]] + double(j) * to.vertices[tri[1]] +
                                 double(kGrid - i - j) * to.vertices[tri[2]]) /
                                double(kGrid);
                            local = std::max(local, distance(from, p));
                          }
                      }
                      raise(local);
                    });
  return beyond ? std::numeric_limits<double>::infinity() : worst.load();
}

// meshoptimizer's collapses within its relative error `target`: the index buffer.
std::vector<uint32_t> collapse(const TriangleMesh& mesh, const std::vector<float>& positions,
                               double target) {
  std::vector<uint32_t> indices = flatIndices(mesh);
  const size_t count = meshopt_simplify(indices.data(), indices.data(), indices.size(),
                                        positions.data(), mesh.vertices.size(), 3 * sizeof(float),
                                        0, float(target), meshopt_SimplifyLockBorder, nullptr);
  indices.resize(count);
  return indices;
}

}  // namespace

double simplifyMesh(TriangleMesh& mesh, MeshAttributes& attributes, double maxError) {
  const bool area = std::any_of(mesh.triangles.begin(), mesh.triangles.end(), [&](const auto& t) {
    const glm::dvec3 &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
    return glm::length(glm::cross(b - a, c - a)) > 0.0;
  });
  if (!area || !(maxError > 0.0)) return 0.0;  // (nothing to measure against)
  // Float positions relative to the lowest corner: far from the origin (UTM) float loses detail.
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  for (const glm::dvec3& v : mesh.vertices) lo = glm::min(lo, v);
  std::vector<float> positions(3 * mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v)
    for (int a = 0; a < 3; ++a) positions[3 * v + size_t(a)] = float(mesh.vertices[v][a] - lo[a]);
  // meshoptimizer's errors are relative to the mesh's extent, and its estimate is of how far
  // vertices move from the planes around them, not of how far a triangle's inside leaves the
  // surface (on a sphere the inside sags about as far again): each result is measured, and the
  // collapses are redone with a target scaled by 0.9 maxError / measured until it is within
  // maxError.
  const double scale =
      meshopt_simplifyScale(positions.data(), mesh.vertices.size(), 3 * sizeof(float));
  const std::unique_ptr<Shape> original = makeMeshShape(mesh);
  double target = maxError;
  for (int attempt = 0; attempt < kSimplifyAttempts; ++attempt) {
    std::vector<uint32_t> indices = collapse(mesh, positions, target / scale);
    if (indices.size() == 3 * mesh.triangles.size()) break;  // nothing collapsed
    TriangleMesh candidate{mesh.vertices, {}};
    candidate.triangles.resize(indices.size() / 3);
    for (size_t t = 0; t < candidate.triangles.size(); ++t)
      candidate.triangles[t] = {indices[3 * t], indices[3 * t + 1], indices[3 * t + 2]};
    const double deviation = sampledDeviation(*original, mesh, candidate, kReach * maxError);
    if (deviation <= maxError) {
      compactMesh(mesh, attributes, indices);
      return deviation;
    }
    // Scaled by how far it went; past the reach that is not known.
    target *= deviation <= kReach * maxError ? 0.9 * maxError / deviation : 0.5 / kReach;
  }
  return 0.0;  // no simplification kept within maxError: the mesh as it was
}

}  // namespace iso
