// Corner values fitted to the points (specs/pipeline.md, "Corner fit"). The corners sample the
// signed distance exactly, but inside a leaf the surface is their trilinear interpolation, which
// runs inside a convex surface and outside a concave one by up to about cell² · curvature / 4:
// on a sphere a leaf of 8 spacings lies 0.1 spacings inside. The octree's patch test allows that
// much, and it is a bias (every leaf of a convex part errs the same way), so it shows as a
// surface shrunk everywhere. Each pass moves every corner by the weighted mean distance of the
// points around it from the interpolated zero set, with the points' trilinear weights in their
// leaves (a Jacobi step of least squares over f(p_i) = 0, normalized so that a uniform offset is
// undone in one pass; a prior of one point's weight on the sampled value keeps corners that few
// points see where they were). Noise averages out over the tens of points a corner sees; the
// bias does not. Hanging corners are snapped again after each pass.
//
// Sums are kept in fixed point and added atomically: integer addition does not depend on the
// order, so the result does not depend on the number of threads.
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <glm/geometric.hpp>

#include "pipeline/base/buffers.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"

namespace iso {
namespace {

constexpr double kWeightScale = 0x1p24;    // Σ w in fixed point
constexpr double kDistanceScale = 0x1p40;  // Σ w r, r in frame units
constexpr double kPrior = 1.0;             // points' weight of a corner's sampled value
// Gradients below this fraction of a distance's (1 per unit) give no distance for a point.
constexpr double kMinGradient = 0.25;

struct Sums {
  int64_t weight = 0, distance = 0;
};

}  // namespace

size_t fitCornersToPoints(CornerField& field, const HangingCorners& hanging, const Octree& tree,
                          const PointSet& points, int passes) {
  if (passes <= 0) return 0;
  std::vector<uint32_t> leaves;
  for (uint32_t i = 0; i < tree.nodes.size(); ++i)
    if (tree.nodes[i].kind == NodeKind::Leaf && tree.nodes[i].pointCount() > 0) leaves.push_back(i);
  SpillVector<Sums> sums(field.size());
  size_t moved = 0;
  for (int pass = 0; pass < passes; ++pass) {
    std::fill(sums.begin(), sums.end(), Sums{});
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, leaves.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
          spillPause();
          for (size_t l = r.begin(); l < r.end(); ++l) {
            const OctreeNode& leaf = tree.nodes[leaves[l]];
            std::array<uint32_t, kCorners> entry{};
            std::array<double, kCorners> value{}, weight{}, weighted{};
            for (int c = 0; c < kCorners; ++c) {
              entry[size_t(c)] = field.find(cornerPoint(leaf.level, leaf.key, c));
              value[size_t(c)] = field.value[entry[size_t(c)]].distance;
            }
            const double size = std::ldexp(1.0, -leaf.level);
            const auto cell = mortonDecode(leaf.key);
            const glm::dvec3 origin = glm::dvec3(cell[0], cell[1], cell[2]) * size;
            for (uint32_t i = leaf.pointBegin; i < leaf.pointEnd; ++i) {
              const glm::dvec3 local = (glm::dvec3(points.position[i]) - origin) / size;
              const std::array<double, 3> u = {std::clamp(local.x, 0.0, 1.0),
                                               std::clamp(local.y, 0.0, 1.0),
                                               std::clamp(local.z, 0.0, 1.0)};
              std::array<double, 3> g{};
              const double f = trilinear(value, u, &g);
              const double gradient = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) / size;
              if (!(gradient > kMinGradient)) continue;
              const double reach = double(points.radius[i]);
              const double distance = std::clamp(f / gradient, -reach, reach);
              const std::array<double, 8> w = trilinearWeights(u);
              for (size_t c = 0; c < kCorners; ++c) {
                weight[c] += w[c];
                weighted[c] += w[c] * distance;
              }
            }
            for (size_t c = 0; c < kCorners; ++c) {
              if (weight[c] == 0.0) continue;
              Sums& s = sums[entry[c]];
              std::atomic_ref<int64_t>(s.weight).fetch_add(std::llround(weight[c] * kWeightScale),
                                                           std::memory_order_relaxed);
              std::atomic_ref<int64_t>(s.distance)
                  .fetch_add(std::llround(weighted[c] * kDistanceScale), std::memory_order_relaxed);
            }
          }
        });
    moved = 0;
    for (size_t e = 0; e < field.size(); ++e) {
      const Sums& s = sums[e];
      if (s.weight == 0) continue;
      const double weight = double(s.weight) / kWeightScale;
      field.value[e].distance -= float(double(s.distance) / kDistanceScale / (weight + kPrior));
      ++moved;
    }
    snapHangingCorners(field, hanging);
  }
  return moved;
}

}  // namespace iso
