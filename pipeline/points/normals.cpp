// Normals by principal component analysis of each point's k nearest neighbours (Hoppe et al.
// 1992): the eigenvector of the smallest eigenvalue of the covariance, computed in double around
// the neighbourhood's mean with cyclic Jacobi rotations, which stay accurate for nearly flat and
// nearly collinear neighbourhoods where closed-form cubic solutions lose digits.
#include <tbb/parallel_for.h>

#include <array>
#include <cmath>
#include <glm/geometric.hpp>

#include "pipeline/base/progress.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

using Matrix3 = std::array<std::array<double, 3>, 3>;

// The eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (Jacobi rotations).
glm::dvec3 smallestEigenvector(Matrix3 a) {
  Matrix3 v = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  for (int sweep = 0; sweep < 32; ++sweep) {
    const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    const double scale = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    if (off <= 1e-30 * scale || off == 0.0) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0.0) continue;
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t =
            std::copysign(1.0, theta) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 3; ++k) {  // A ← Jᵀ A J
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
  }
  int smallest = 0;
  for (int i = 1; i < 3; ++i)
    if (a[i][i] < a[smallest][smallest]) smallest = i;
  return glm::dvec3(v[0][smallest], v[1][smallest], v[2][smallest]);
}

}  // namespace

size_t estimateNormals(PointSet& points, const Neighbors& neighbors) {
  const size_t n = points.size(), k = size_t(neighbors.k);
  if (points.normal.empty()) points.normal.assign(n, glm::vec3(0.0f));
  std::vector<uint8_t> estimated(n, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 2048),
                    [&](const tbb::blocked_range<size_t>& range) {
                      progressAdvance(range.size());
                      for (size_t i = range.begin(); i < range.end(); ++i) {
                        if (points.normal[i] != glm::vec3(0.0f)) continue;
                        glm::dvec3 mean(points.position[i]);
                        for (size_t j = 0; j < k; ++j)
                          mean += glm::dvec3(points.position[neighbors.index[i * k + j]]);
                        mean /= double(k + 1);
                        Matrix3 c{};
                        const auto add = [&](const glm::vec3& p) {
                          const glm::dvec3 d = glm::dvec3(p) - mean;
                          for (int r = 0; r < 3; ++r)
                            for (int s = 0; s < 3; ++s) c[size_t(r)][size_t(s)] += d[r] * d[s];
                        };
                        add(points.position[i]);
                        for (size_t j = 0; j < k; ++j)
                          add(points.position[neighbors.index[i * k + j]]);
                        const glm::dvec3 normal = smallestEigenvector(c);
                        const double length = glm::length(normal);
                        points.normal[i] =
                            length > 0.0 ? glm::vec3(normal / length) : glm::vec3(0.0f, 0.0f, 1.0f);
                        estimated[i] = 1;
                      }
                    });
  size_t count = 0;
  for (uint8_t e : estimated) count += e;
  return count;
}

float roughnessOf(const PointSet& points, uint32_t i, const uint32_t* neighbors, size_t k) {
  // Only neighbours of the same surface: a second sheet within reach (opposite normals) is shape,
  // not noise.
  thread_local std::vector<uint32_t> same;
  same.assign(1, i);
  for (size_t j = 0; j < k; ++j)
    if (glm::dot(points.normal[i], points.normal[neighbors[j]]) > 0.5f) same.push_back(neighbors[j]);
  glm::dvec3 mean(0.0);
  for (uint32_t m : same) mean += glm::dvec3(points.position[m]);
  mean /= double(same.size());
  const glm::dvec3 normal(points.normal[i]);
  double sum = 0.0;
  for (uint32_t m : same) {
    const double d = glm::dot(glm::dvec3(points.position[m]) - mean, normal);
    sum += d * d;
  }
  return float(std::sqrt(sum / double(same.size())));
}

void estimateRoughness(PointSet& points, const Neighbors& neighbors) {
  const size_t n = points.size(), k = size_t(neighbors.k);
  points.roughness.assign(n, 0.0f);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<size_t>& range) {
                      for (size_t i = range.begin(); i < range.end(); ++i)
                        points.roughness[i] =
                            roughnessOf(points, uint32_t(i), neighbors.index.data() + i * k, k);
                    });
}

}  // namespace iso
