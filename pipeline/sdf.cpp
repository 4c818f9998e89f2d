// The signed distance at a corner Q (specs/pipeline.md, "Signed distance"): Gaussian weights
// w_i = exp(-|Q - p_i|² / 2σ_i²) with σ_i = max(smoothing · r_i, minSigma), truncated where they
// fall below e^-4.5 of the largest, p̄ = Σ w_i p_i / Σ w_i, n̄ = Σ w_i n_i / |Σ w_i n_i|,
// f(Q) = (Q - p̄)·n̄.
//
// Deviations from the paper, each for a defined answer in a hard case:
// - weights are computed relative to the largest (log-sum-exp shift), so exp() never underflows
//   however far Q is from the points, and the truncation is relative, so the support always
//   reaches Q (a large leaf's corners can be farther than every r_i from the points);
// - only points whose normal is within 120° of the dominant point's normal take part, so two
//   sheets closer than the radius with opposite normals do not cancel: Q sees the sheet it is
//   nearest to (in σ units);
// - if the normals still cancel, n̄ is the dominant point's normal.
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

#include "knn.h"
#include "stages.h"

namespace iso {
namespace {

constexpr size_t kProbe = 4;              // nearest points that set the search radius
constexpr double kTruncation = 2.0;       // relative log-weight below which weights are 0 (2σ)
constexpr float kOpposingNormal = -0.5f;  // cos 120°

// The signed distance from Q (the origin) to the algebraic sphere s(x) = u0 + u·x + u4 |x|² fitted
// to the weighted points and normals (APSS, Guennebaud & Gross 2007, eqs. 7–9), from weighted
// means relative to Q: p̄, n̄ (not normalized), mean p·n and mean p·p. Along the gradient the
// root of s is at 2 u0 / (|u| + sqrt(|u|² - 4 u0 u4)), a form that stays exact as u4 → 0 (a
// plane). Spheres smaller than σ are flattened to radius σ (noise is not curvature).
double sphereDistance(const glm::dvec3& pMean, const glm::dvec3& nMean, double pn, double pp,
                      double sigma) {
  const double variance = pp - glm::dot(pMean, pMean);
  double u4 = variance > 1e-30 ? 0.5 * (pn - glm::dot(pMean, nMean)) / variance : 0.0;
  u4 = std::clamp(u4, -0.5 / sigma, 0.5 / sigma);
  const glm::dvec3 u = nMean - 2.0 * u4 * pMean;
  const double u0 = -(glm::dot(u, pMean) + u4 * pp);
  const double gradient = glm::length(u);
  if (!(gradient > 0.0)) return 0.0;
  const double discriminant = gradient * gradient - 4.0 * u0 * u4;
  if (discriminant < 0.0) return u0 / gradient;  // no real sphere through the gradient line
  return 2.0 * u0 / (gradient + std::sqrt(discriminant));
}

}  // namespace

SdfEvaluator::SdfEvaluator(const PointSet& points, const KdTree& tree, double smoothing,
                           FitMode fit)
    : points_(points), tree_(tree), smoothing_(smoothing), fit_(fit) {}

uint32_t SdfEvaluator::nearest(const glm::dvec3& q, float& distance) const {
  uint32_t index = 0;
  float d2 = 0.0f;
  tree_.nearest(glm::vec3(q), 1, &index, &d2);
  distance = std::sqrt(d2);
  return index;
}

CornerSample SdfEvaluator::evaluate(const glm::dvec3& q, float minSigma) const {
  thread_local std::vector<std::pair<uint32_t, float>> found;
  thread_local std::vector<double> logWeight;
  const glm::vec3 qf(q);
  std::array<uint32_t, kProbe> probe{};
  std::array<float, kProbe> probeD2{};
  const size_t probes = tree_.nearest(qf, kProbe, probe.data(), probeD2.data());
  CornerSample out;
  if (probes == 0) return out;
  const auto sigmaOf = [&](uint32_t i) {
    return std::max(smoothing_ * double(points_.radius[i]), double(minSigma));
  };
  // Every point with a relative weight above e^-4.5 lies within this radius when its σ is at most
  // the largest σ among the nearest points (specs/pipeline.md derives it).
  double sigmaMax = 0.0;
  for (size_t j = 0; j < probes; ++j) sigmaMax = std::max(sigmaMax, sigmaOf(probe[j]));
  const double sigma0 = sigmaOf(probe[0]);
  const double d0Squared = double(probeD2[0]);
  const double radius =
      sigmaMax * std::sqrt(d0Squared / (sigma0 * sigma0) + 2.0 * kTruncation) * 1.0001;
  tree_.withinRadius(qf, float(radius), found);
  if (found.empty()) found.push_back({probe[0], probeD2[0]});

  logWeight.resize(found.size());
  double best = -1e300;
  uint32_t dominant = found[0].first;
  for (size_t j = 0; j < found.size(); ++j) {
    const uint32_t i = found[j].first;
    const glm::dvec3 d = glm::dvec3(points_.position[i]) - q;
    const double sigma = sigmaOf(i);
    logWeight[j] = -glm::dot(d, d) / (2.0 * sigma * sigma);
    if (logWeight[j] > best) {
      best = logWeight[j];
      dominant = i;
    }
  }
  const glm::vec3 reference = points_.normal[dominant];
  double weightSum = 0.0, dotSum = 0.0, squareSum = 0.0;  // Σw p·n and Σw p·p, p relative to Q
  glm::dvec3 offsetSum(0.0), normalSum(0.0), colorSum(0.0);
  for (size_t j = 0; j < found.size(); ++j) {
    const double relative = logWeight[j] - best;
    if (relative < -kTruncation) continue;
    const uint32_t i = found[j].first;
    if (glm::dot(points_.normal[i], reference) < kOpposingNormal) continue;
    const double w = std::exp(relative) * double(points_.weight[i]);
    const glm::dvec3 p = glm::dvec3(points_.position[i]) - q;
    const glm::dvec3 n(points_.normal[i]);
    weightSum += w;
    offsetSum += w * p;
    normalSum += w * n;
    dotSum += w * glm::dot(p, n);
    squareSum += w * glm::dot(p, p);
    if (points_.hasColors()) colorSum += w * glm::dvec3(points_.color[i]);
  }
  const double normalLength = glm::length(normalSum);
  const glm::dvec3 normal =
      normalLength > 1e-9 * weightSum ? normalSum / normalLength : glm::dvec3(reference);
  const glm::dvec3 mean = offsetSum / weightSum;  // p̄ - Q
  out.distance = float(-glm::dot(mean, normal));  // (Q - p̄)·n̄
  if (fit_ == FitMode::Sphere && normalLength > 1e-9 * weightSum) {
    out.distance = float(sphereDistance(mean, normalSum / weightSum, dotSum / weightSum,
                                        squareSum / weightSum, sigmaOf(dominant)));
  }
  out.normal = glm::vec3(normal);
  if (points_.hasColors()) out.color = glm::vec3(colorSum / weightSum);
  return out;
}

}  // namespace iso
