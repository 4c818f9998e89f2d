// The signed distance at a corner Q (specs/pipeline.md, "Signed distance"): Gaussian weights
// w_i = exp(-|Q - p_i|² / 2σ_i²) with σ_i = max(smoothing · r_i, minSigma), truncated where they
// fall below e^-2 of the largest, p̄ = Σ w_i p_i / Σ w_i, n̄ = Σ w_i n_i / |Σ w_i n_i|,
// f(Q) = (Q - p̄)·n̄ (the paper's plane), or the distance to an algebraic sphere (--fit sphere).
//
// Deviations from the paper, each for a defined answer in a hard case:
// - weights are computed relative to the largest (log-sum-exp shift), so exp() never underflows
//   however far Q is from the points, and the truncation is relative, so the support always
//   reaches Q (a large leaf's corners can be farther than every r_i from the points);
// - where the normals turn by more than 60° within the kernel (a sharp edge), the two faces are
//   fitted on their own and combined as solids, so that the edge stays sharp; points whose normal
//   opposes the face's (a few wrong normals) are left out;
// - when they do not (two sheets closer than the radius with opposite normals, whose normals
//   would cancel), each side is fitted on its own and the two are combined as solids: the slab
//   between sheets facing away from each other is inside (the larger distance), the gap between
//   sheets facing each other is outside (the smaller);
// - a group whose normals cancel takes the dominant point's normal.
#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>

#include "pipeline/base/options.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr size_t kProbe = 4;              // nearest points that set the search radius
constexpr double kTruncation = 2.0;       // relative log-weight below which weights are 0 (2σ)
constexpr float kOpposingNormal = -0.5f;  // cos 120°
constexpr float kFaceAngleCos = 0.8660254f;  // cos 30°: the normals of one face of a feature
constexpr double kFeatureAngleCos = 0.5;     // cos 60°: two faces make a feature
constexpr size_t kMinGroupPoints = 3;
// |Σ w n| / Σ w of the second face at least: its normals point one way (a face), not every way
// (noise, which the one fit averages better).
constexpr double kCoherentNormals = 0.95;
constexpr double kMinorGroup = 0.1;       // a group of opposing normals below this count is noise
constexpr double kReach = 0.25;           // σ floor in distances to the nearest point

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

// e^x for x in [-kTruncation, 0], relative error below 1e-10: the Taylor polynomial of degree 8
// of e^(x/8), raised to the 8th power by squaring three times. Branch-free, so that the weight
// loop vectorizes.
inline double expAbove(double x) {
  constexpr std::array<double, 9> kTaylor = {1.0,         1.0,          1.0 / 2,
                                             1.0 / 6,     1.0 / 24,     1.0 / 120,
                                             1.0 / 720,   1.0 / 5040,   1.0 / 40320};
  const double y = x * 0.125;
  double e = kTaylor[8];
  for (int j = 7; j >= 0; --j) e = e * y + kTaylor[size_t(j)];
  e *= e;
  e *= e;
  return e * e;
}

// Weighted sums of one group of points (relative to Q) and the surface fitted to them.
struct FitSums {
  double weight = 0.0, pn = 0.0, pp = 0.0;  // Σw, Σw p·n, Σw p·p
  glm::dvec3 p{0.0}, n{0.0}, color{0.0};    // Σw p, Σw n, Σw c
  size_t count = 0;

  void add(double w, const glm::dvec3& position, const glm::dvec3& normal, const glm::vec3* c) {
    ++count;
    weight += w;
    p += w * position;
    n += w * normal;
    pn += w * glm::dot(position, normal);
    pp += w * glm::dot(position, position);
    if (c) color += w * glm::dvec3(*c);
  }

  // The sample of this group's surface at Q (the origin).
  CornerSample sample(FitMode fit, double sigma, const glm::vec3& fallbackNormal) const {
    CornerSample out;
    const double length = glm::length(n);
    const bool oriented = length > 1e-9 * weight;
    const glm::dvec3 normal = oriented ? n / length : glm::dvec3(fallbackNormal);
    const glm::dvec3 mean = p / weight;             // p̄ - Q
    out.distance = float(-glm::dot(mean, normal));  // (Q - p̄)·n̄
    if (fit == FitMode::Sphere && oriented)
      out.distance = float(sphereDistance(mean, n / weight, pn / weight, pp / weight, sigma));
    out.normal = glm::vec3(normal);
    out.color = glm::vec3(color / weight);
    return out;
  }

  FitSums operator+(const FitSums& o) const {
    FitSums sum = *this;
    sum.count += o.count;
    sum.weight += o.weight;
    sum.p += o.p;
    sum.n += o.n;
    sum.pn += o.pn;
    sum.pp += o.pp;
    sum.color += o.color;
    return sum;
  }
};

// Two fitted surfaces combined as solids: where the second group's points lie behind the first's
// surface (a slab between sheets facing away from each other, a convex edge) the inside is the
// intersection of the two solids (the larger distance); otherwise (a gap between sheets facing
// each other, a concave edge) their union (the smaller).
CornerSample combineSolids(const FitSums& first, const FitSums& second, FitMode fit,
                           double sigma, const glm::vec3& firstAxis, const glm::vec3& secondAxis) {
  const CornerSample a = first.sample(fit, sigma, firstAxis);
  const CornerSample b = second.sample(fit, sigma, secondAxis);
  const bool intersection =
      glm::dot(second.p / second.weight - first.p / first.weight, glm::dvec3(a.normal)) < 0.0;
  return (intersection ? a.distance >= b.distance : a.distance <= b.distance) ? a : b;
}

// Whether a group of `count` points is large enough beside one of `other` to be a surface of its
// own rather than a few stray normals.
bool isGroup(size_t count, size_t other) {
  return count >= kMinGroupPoints && double(count) >= kMinorGroup * double(other);
}

// The fit where the normals do not oppose: one surface, or a sharp feature (beyond the paper;
// specs/pipeline.md §4). The points whose normal is within kFaceAngle of the normal near Q (the
// dominant point's, averaged over the points that agree with it) are one face; the others whose
// normal does not oppose it, when they are a group of their own whose normals agree with each
// other and whose mean normal turns more than 60° from the face's, are another; the two are fitted on their own and combined
// as solids (convex edge: intersection; concave: union), so that an edge stays sharp instead of
// being rounded over the kernel's width, with the right sign on both sides of it. Points whose
// normal opposes the face (a few wrong normals) are left out.
CornerSample faceSample(const PointSet& points, const glm::dvec3& q, FitMode fit,
                        const std::vector<std::pair<uint32_t, float>>& found,
                        const std::vector<double>& weight, const FitSums& all, double sigma,
                        const glm::vec3& axis) {
  glm::dvec3 near(0.0);
  for (size_t j = 0; j < found.size(); ++j) {
    const glm::vec3& n = points.normal[found[j].first];
    if (weight[j] > 0.0 && glm::dot(n, axis) >= kFaceAngleCos) near += weight[j] * glm::dvec3(n);
  }
  const double length = glm::length(near);
  if (!(length > 0.0)) return all.sample(fit, sigma, axis);
  near /= length;
  FitSums face, other;
  size_t opposing = 0;
  for (size_t j = 0; j < found.size(); ++j) {
    if (weight[j] == 0.0) continue;
    const uint32_t i = found[j].first;
    const double c = glm::dot(near, glm::dvec3(points.normal[i]));
    if (c < kOpposingNormal) {
      ++opposing;
      continue;
    }
    const glm::vec3* color = points.hasColors() ? &points.color[i] : nullptr;
    (c >= kFaceAngleCos ? face : other)
        .add(weight[j], glm::dvec3(points.position[i]) - q, glm::dvec3(points.normal[i]), color);
  }
  if (face.count == 0) return all.sample(fit, sigma, axis);
  const bool feature = isGroup(other.count, face.count) && isGroup(face.count, other.count) &&
                       glm::length(other.n) >= kCoherentNormals * other.weight &&
                       glm::dot(face.n, other.n) <
                           kFeatureAngleCos * glm::length(face.n) * glm::length(other.n);
  if (feature)
    return combineSolids(face, other, fit, sigma, glm::vec3(near), glm::vec3(other.n));
  if (opposing == 0) return all.sample(fit, sigma, glm::vec3(near));
  return (other.count > 0 ? face + other : face).sample(fit, sigma, glm::vec3(near));
}

}  // namespace

SdfEvaluator::SdfEvaluator(const PointSet& points, const PointIndex& tree, double smoothing,
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
  return *sample(q, minSigma, HUGE_VAL);
}

std::optional<CornerSample> SdfEvaluator::evaluateWithin(const glm::dvec3& q, float minSigma,
                                                         double reach) const {
  return sample(q, minSigma, reach);
}

std::optional<CornerSample> SdfEvaluator::sample(const glm::dvec3& q, float minSigma,
                                                 double reach) const {
  thread_local std::vector<std::pair<uint32_t, float>> found;
  thread_local std::vector<double> logWeight, weight;
  const glm::vec3 qf(q);
  std::array<uint32_t, kProbe> probe{};
  std::array<float, kProbe> probeD2{};
  const size_t probes = tree_.nearest(qf, kProbe, probe.data(), probeD2.data());
  const bool bounded = reach < HUGE_VAL;
  // Within a reach, the nearest points must be the same as those of any superset of these points
  // that agrees with them inside the reach: all kProbe of them found, none farther than it.
  if (bounded && (probes < kProbe || double(probeD2[kProbe - 1]) > reach * reach))
    return std::nullopt;
  if (probes == 0) return CornerSample{};
  // σ grows with the distance to the nearest point: far from the points a common scale ranks them
  // by distance, where their own radii would rank them by radius.
  const double floor = std::max(double(minSigma), kReach * std::sqrt(double(probeD2[0])));
  const auto sigmaOf = [&](uint32_t i) {
    return std::max(smoothing_ * double(points_.radius[i]), floor);
  };
  // Every point with a relative weight above e^-2 lies within this radius when its σ is at most
  // the largest σ among the nearest points (specs/pipeline.md derives it).
  double sigmaMax = 0.0;
  for (size_t j = 0; j < probes; ++j) sigmaMax = std::max(sigmaMax, sigmaOf(probe[j]));
  const double sigma0 = sigmaOf(probe[0]);
  const double radius =
      sigmaMax * std::sqrt(double(probeD2[0]) / (sigma0 * sigma0) + 2.0 * kTruncation) * 1.0001;
  if (bounded && radius > reach) return std::nullopt;
  tree_.withinRadius(qf, float(radius), found);
  if (found.empty()) found.push_back({probe[0], probeD2[0]});

  // Log-weights -d²/2σ_i² from the index's squared distances (float: relative error 1e-7, far
  // below what changes a weight), with 1/2σ_i² = min(1/2(smoothing·r_i)², 1/2·floor²).
  const double inverseFloor = floor > 0.0 ? 0.5 / (floor * floor) : HUGE_VAL;
  logWeight.resize(found.size());
  double best = -HUGE_VAL;
  size_t dominantAt = 0;
  for (size_t j = 0; j < found.size(); ++j) {
    logWeight[j] = -double(found[j].second) *
                   std::min(double(halfInverseSigma2(found[j].first)), inverseFloor);
    if (logWeight[j] > best) {
      best = logWeight[j];
      dominantAt = j;
    }
  }
  const uint32_t dominant = found[dominantAt].first;
  weight.resize(found.size());
  for (size_t j = 0; j < found.size(); ++j) {
    const double relative = logWeight[j] - best;
    weight[j] = relative >= -kTruncation ? expAbove(relative) : 0.0;
  }
  // Split the points by the side their normal faces, relative to the dominant point's normal.
  const glm::vec3 axis = points_.normal[dominant];
  FitSums with, against;
  for (size_t j = 0; j < found.size(); ++j) {
    if (weight[j] == 0.0) continue;
    const uint32_t i = found[j].first;
    const double w = weight[j] * double(points_.weight[i]);
    weight[j] = w;
    const glm::dvec3 p = glm::dvec3(points_.position[i]) - q, n(points_.normal[i]);
    const glm::vec3* color = points_.hasColors() ? &points_.color[i] : nullptr;
    (glm::dot(points_.normal[i], axis) >= 0.0f ? with : against).add(w, p, n, color);
  }
  const FitSums all = with + against;
  const double sigma = sigmaOf(dominant);
  // Two sides when many points face against the dominant one and the two groups oppose each other
  // (two sheets closer than the radius). Counted, not weighted: far from the sheets the weights
  // favour whichever points are nearest sideways, not the nearer sheet.
  const bool twoSided =
      against.count >= kMinorGroup * double(with.count) &&
      glm::dot(with.n, against.n) < kOpposingNormal * glm::length(with.n) * glm::length(against.n);
  if (!twoSided) return faceSample(points_, q, fit_, found, weight, all, sigma, axis);
  return combineSolids(with, against, fit_, sigma, axis, -axis);
}

}  // namespace iso
