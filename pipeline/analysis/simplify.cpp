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
// Where a result goes beyond maxError, the triangles around are frozen; past a vertex in kShare,
// the measure stops looking and the target is halved too.
constexpr size_t kShare = 200;

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

// Where a simplified mesh leaves its original by more than the error allowed.
struct Deviation {
  double largest = 0.0;            // the largest sampled distance within the error (world units)
  std::vector<uint32_t> vertices;  // vertices near the samples beyond it (sorted, unique)
  bool tooMany = false;            // more than the cap of them: stopped looking
};

// The distance between a mesh and its simplification (which uses a subset of its vertices),
// sampled both ways: from every vertex the simplification dropped to it, and from a grid of points
// on each of its triangles to the mesh. Samples farther than `limit` (the searches open no box
// beyond it) give the vertices near them: the dropped vertex, or the triangle's corners.
Deviation measureDeviation(const Shape& original, const TriangleMesh& mesh,
                           const TriangleMesh& simplified, double limit, size_t cap) {
  const std::unique_ptr<Shape> simplifiedShape = makeMeshShape(simplified);
  std::vector<uint8_t> kept(mesh.vertices.size(), 0);
  for (const auto& t : simplified.triangles)
    for (uint32_t v : t) kept[v] = 1;
  std::atomic<double> largest{0.0};
  std::atomic<size_t> found{0};
  std::vector<std::atomic<uint8_t>> beyond(mesh.vertices.size());  // set from many threads
  const auto raise = [&](double d) {
    double seen = largest.load();
    while (d > seen && !largest.compare_exchange_weak(seen, d)) {
    }
  };
  // The distance from p to shape, or -1 past the limit.
  const auto distance = [&](const Shape& shape, const glm::dvec3& p) {
    const std::optional<ClosestPoint> c = shape.closestWithin(p, limit);
    return c ? c->distance : -1.0;
  };
  tbb::parallel_for(tbb::blocked_range<size_t>(0, mesh.vertices.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      double local = 0.0;
                      for (size_t v = r.begin(); v < r.end() && found <= cap; ++v) {
                        if (kept[v]) continue;
                        const double d = distance(*simplifiedShape, mesh.vertices[v]);
                        if (d >= 0.0) {
                          local = std::max(local, d);
                        } else {
                          beyond[v].store(1, std::memory_order_relaxed);
                          ++found;
                        }
                      }
                      raise(local);
                    });
  constexpr int kGrid = 6;  // points a triangle edge is cut into
  tbb::parallel_for(tbb::blocked_range<size_t>(0, simplified.triangles.size(), 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      double local = 0.0;
                      for (size_t t = r.begin(); t < r.end() && found <= cap; ++t) {
                        const auto& tri = simplified.triangles[t];
                        const auto& p = simplified.vertices;
                        bool far = false;
                        for (int i = 0; i <= kGrid && !far; ++i)
                          for (int j = 0; i + j <= kGrid && !far; ++j) {
                            if (i == kGrid || j == kGrid || i + j == 0) continue;  // corners
                            const glm::dvec3 q = (double(i) * p[tri[0]] + double(j) * p[tri[1]] +
                                                  double(kGrid - i - j) * p[tri[2]]) /
                                                 double(kGrid);
                            const double d = distance(original, q);
                            if (d >= 0.0)
                              local = std::max(local, d);
                            else
                              far = true;
                          }
                        if (far) {
                          for (uint32_t v : tri) beyond[v].store(1, std::memory_order_relaxed);
                          ++found;
                        }
                      }
                      raise(local);
                    });
  Deviation out;
  out.largest = largest.load();
  out.tooMany = found > cap;
  for (uint32_t v = 0; v < beyond.size(); ++v)
    if (beyond[v].load(std::memory_order_relaxed)) out.vertices.push_back(v);
  return out;
}

// meshoptimizer's collapses of the triangles not `frozen`, within its relative error `target`
// (their borders with frozen ones stay, as open borders do), and the frozen ones as they were: the
// index buffer.
std::vector<uint32_t> collapse(const TriangleMesh& mesh, const std::vector<float>& positions,
                               const std::vector<uint8_t>& frozen, double target) {
  std::vector<uint32_t> free, indices;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    std::vector<uint32_t>& to = frozen[t] ? indices : free;
    to.insert(to.end(), mesh.triangles[t].begin(), mesh.triangles[t].end());
  }
  const size_t count = meshopt_simplify(free.data(), free.data(), free.size(), positions.data(),
                                        mesh.vertices.size(), 3 * sizeof(float), 0, float(target),
                                        meshopt_SimplifyLockBorder, nullptr);
  free.resize(count);
  indices.insert(indices.end(), free.begin(), free.end());
  return indices;
}

// Freeze the triangles that use `vertices`.
void freezeAround(const TriangleMesh& mesh, const std::vector<uint32_t>& vertices,
                  std::vector<uint8_t>& frozen) {
  std::vector<uint8_t> near(mesh.vertices.size(), 0);
  for (uint32_t v : vertices) near[v] = 1;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    if (near[tri[0]] || near[tri[1]] || near[tri[2]]) frozen[t] = 1;
  }
}

// Float positions relative to the lowest corner (far from the origin, UTM, float loses detail).
std::vector<float> floatPositions(const TriangleMesh& mesh) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity());
  for (const glm::dvec3& v : mesh.vertices) lo = glm::min(lo, v);
  std::vector<float> positions(3 * mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v)
    for (int a = 0; a < 3; ++a) positions[3 * v + size_t(a)] = float(mesh.vertices[v][a] - lo[a]);
  return positions;
}

}  // namespace

void collapseMesh(TriangleMesh& mesh, MeshAttributes& attributes, double target) {
  if (mesh.triangles.empty() || !(target > 0.0)) return;
  const std::vector<float> positions = floatPositions(mesh);
  const double scale =
      meshopt_simplifyScale(positions.data(), mesh.vertices.size(), 3 * sizeof(float));
  if (!(scale > 0.0)) return;
  std::vector<uint32_t> indices =
      collapse(mesh, positions, std::vector<uint8_t>(mesh.triangles.size(), 0), target / scale);
  compactMesh(mesh, attributes, indices);
}

double simplifyMesh(TriangleMesh& mesh, MeshAttributes& attributes, double maxError) {
  const bool area = std::any_of(mesh.triangles.begin(), mesh.triangles.end(), [&](const auto& t) {
    const glm::dvec3 &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
    return glm::length(glm::cross(b - a, c - a)) > 0.0;
  });
  if (!area || !(maxError > 0.0)) return 0.0;  // (nothing to measure against)
  const std::vector<float> positions = floatPositions(mesh);
  // meshoptimizer's errors are relative to the mesh's extent, and its estimate is of how far
  // vertices move from the planes around them, not of how far the result leaves the mesh (a
  // needle's tip collapses into its base at almost no cost; on a sphere a triangle's inside sags
  // about as far again): each result is measured; where there were many places beyond maxError,
  // the target is halved, else the triangles around them are frozen and the rest collapsed again.
  const double scale =
      meshopt_simplifyScale(positions.data(), mesh.vertices.size(), 3 * sizeof(float));
  const std::unique_ptr<Shape> original = makeMeshShape(mesh);
  const size_t cap = std::max<size_t>(64, mesh.vertices.size() / kShare);
  std::vector<uint8_t> frozen(mesh.triangles.size(), 0);
  double target = maxError;
  for (int attempt = 0; attempt < kSimplifyAttempts; ++attempt) {
    std::vector<uint32_t> indices = collapse(mesh, positions, frozen, target / scale);
    if (indices.size() == 3 * mesh.triangles.size()) break;  // nothing collapsed
    TriangleMesh candidate{mesh.vertices, {}};
    candidate.triangles.resize(indices.size() / 3);
    for (size_t t = 0; t < candidate.triangles.size(); ++t)
      candidate.triangles[t] = {indices[3 * t], indices[3 * t + 1], indices[3 * t + 2]};
    const Deviation deviation = measureDeviation(*original, mesh, candidate, maxError, cap);
    if (deviation.vertices.empty()) {
      compactMesh(mesh, attributes, indices);
      return deviation.largest;
    }
    if (deviation.tooMany)  // (which were found then depends on the threads' timing)
      target *= 0.5;
    else
      freezeAround(mesh, deviation.vertices, frozen);
  }
  return 0.0;  // no simplification kept within maxError: the mesh as it was
}

}  // namespace iso
