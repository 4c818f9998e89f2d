#include "pipeline/analysis/evaluate.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <numbers>

#include "iso/check.h"
#include "iso/quantize.h"
#include "iso/reader.h"
#include "pipeline/analysis/measure.h"
#include "pipeline/geom/random.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

// Weighted distances and, in units of the point spacing, the shares beyond half a spacing and two,
// and the RMS of the bulk within two spacings: the one summary every metric here reports.
struct Weighted {
  double spacing = 0.0;  // 0: no shares
  double sum = 0.0, squares = 0.0, weight = 0.0, max = 0.0;
  double beyondHalf = 0.0, beyondTwo = 0.0, bulkSquares = 0.0;
  std::optional<glm::dvec3> maxAt;  // world units, where the caller says
  void add(double d, double w, std::optional<glm::dvec3> at = std::nullopt) {
    sum += w * d;
    squares += w * d * d;
    weight += w;
    if (d >= max) {
      max = d;
      maxAt = at;
    }
    if (d > 0.5 * spacing) beyondHalf += w;
    if (d > 2.0 * spacing)
      beyondTwo += w;
    else
      bulkSquares += w * d * d;
  }
  double mean() const { return weight > 0 ? sum / weight : 0.0; }
  double rms() const { return weight > 0 ? std::sqrt(squares / weight) : 0.0; }
  double share(double w) const { return weight > 0 ? w / weight : 0.0; }
  double bulkRms() const {
    return weight > beyondTwo ? std::sqrt(bulkSquares / (weight - beyondTwo)) : 0.0;
  }
};

glm::dvec3 toWorld(const Vec3& p, const Frame& f) {
  return toWorld(glm::dvec3(p[0], p[1], p[2]), f);
}

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  const size_t i = std::min(values.size() - 1, size_t(q * double(values.size())));
  std::nth_element(values.begin(), values.begin() + ptrdiff_t(i), values.end());
  return values[i];
}

struct IsoToTruth {
  Weighted distance;
  std::vector<double> normalAngles;  // degrees
  std::vector<glm::vec3> samples;    // frame units, for the fallback of truth → iso
};

IsoToTruth isoToTruth(const SurfaceModel& surface, const Shape& truth, const EvalOptions& options,
                      double spacing) {
  const Frame& frame = surface.header().frame;
  const std::vector<ZeroSetSample> samples = surface.sampleZeroSet(options.linesPerEdge);
  std::vector<double> distance(samples.size()), angle(samples.size());
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, samples.size(), 1024),
      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const ClosestPoint c = truth.closest(toWorld(samples[i].position, frame));
          distance[i] = c.distance;
          const SurfaceEval e = surface.evaluate(samples[i].leaf, samples[i].position);
          double dot = glm::dot(glm::dvec3(e.normal[0], e.normal[1], e.normal[2]), c.normal);
          if (!options.orientedNormals) dot = std::abs(dot);
          angle[i] = std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / std::numbers::pi;
        }
      });
  IsoToTruth out;
  out.distance.spacing = spacing;
  for (size_t i = 0; i < samples.size(); ++i) {
    out.distance.add(distance[i], samples[i].area, toWorld(samples[i].position, frame));
    out.samples.push_back(glm::vec3(float(samples[i].position[0]), float(samples[i].position[1]),
                                    float(samples[i].position[2])));
  }
  out.normalAngles = std::move(angle);
  // The largest distance, refined: a thin part of the zero set (a fin at a sharp edge) can slip
  // between the lines, most in large leaves. The leaves that came within half the largest and
  // those whose corners change sign but gave no sample are sampled again, 8 times as densely;
  // their samples count towards the largest distance only (the area was weighed above).
  std::vector<double> leafMax(surface.leaves().size(), -1.0);
  for (size_t i = 0; i < samples.size(); ++i)
    leafMax[samples[i].leaf] = std::max(leafMax[samples[i].leaf], distance[i]);
  std::vector<uint32_t> again;
  for (uint32_t id = 0; id < leafMax.size(); ++id) {
    if (leafMax[id] >= 0.5 * out.distance.max) {
      again.push_back(id);
    } else if (leafMax[id] < 0.0) {
      int negative = 0;
      for (const uint32_t c : surface.leaves()[id].corners)
        negative += surface.corners().distance[c] < 0.0f;
      if (negative != 0 && negative != kCorners) again.push_back(id);
    }
  }
  const std::vector<ZeroSetSample> dense = surface.sampleZeroSet(8 * options.linesPerEdge, again);
  std::vector<double> denseDistance(dense.size());
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, dense.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i)
          denseDistance[i] = truth.closest(toWorld(dense[i].position, frame)).distance;
      });
  for (size_t i = 0; i < dense.size(); ++i)
    out.distance.add(denseDistance[i], 0.0, toWorld(dense[i].position, frame));
  return out;
}

struct TruthToIso {
  Weighted distance;
  uint64_t unprojected = 0;
};

// The point of the zero set closest to p (frame units): projection from p, or from the nearest
// zero-set sample when p lies in empty space, refined by moving along the tangent plane toward p
// and projecting again (alternating projections converge to the closest point of a smooth patch).
std::optional<glm::dvec3> closestOnZeroSet(const SurfaceModel& surface, const glm::dvec3& p,
                                           const PointIndex& samples,
                                           const std::vector<glm::vec3>& samplePositions) {
  std::optional<Vec3> x = surface.project({p.x, p.y, p.z});
  if (!x && samples.size() > 0) {
    uint32_t nearest = 0;
    float d2 = 0.0f;
    samples.nearest(glm::vec3(p), 1, &nearest, &d2);
    const glm::dvec3 s(samplePositions[nearest]);
    x = surface.project({s.x, s.y, s.z});
  }
  if (!x) return std::nullopt;
  glm::dvec3 c((*x)[0], (*x)[1], (*x)[2]);
  for (int i = 0; i < 4; ++i) {
    const uint32_t leaf = surface.findLeaf({c.x, c.y, c.z});
    if (leaf == kNoNode) break;
    const SurfaceEval e = surface.evaluate(leaf, {c.x, c.y, c.z});
    const glm::dvec3 g(e.gradient[0], e.gradient[1], e.gradient[2]);
    if (!(glm::dot(g, g) > 0.0)) break;
    const glm::dvec3 n = glm::normalize(g), toward = p - c;
    const glm::dvec3 y = c + (toward - glm::dot(toward, n) * n);
    const std::optional<Vec3> next = surface.project({y.x, y.y, y.z});
    if (!next) break;
    const glm::dvec3 candidate((*next)[0], (*next)[1], (*next)[2]);
    if (glm::length(candidate - p) >= glm::length(c - p)) break;
    c = candidate;
  }
  return c;
}

TruthToIso truthToIso(const SurfaceModel& surface, const Shape& truth,
                      const std::vector<glm::vec3>& isoSamples, const EvalOptions& options,
                      double spacing) {
  const Frame& frame = surface.header().frame;
  std::mt19937_64 rng(options.seed);
  std::vector<glm::dvec3> points(options.truthSamples);
  for (glm::dvec3& p : points) p = truth.sample(rng).position;
  const PointIndex tree(isoSamples);
  std::vector<double> distance(points.size());
  std::vector<uint8_t> projected(points.size());
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, points.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const glm::dvec3 p = toFrame(points[i], frame);
          if (const std::optional<glm::dvec3> x = closestOnZeroSet(surface, p, tree, isoSamples)) {
            distance[i] = glm::length(*x - p) * frame.size;
            projected[i] = 1;
          } else if (tree.size() > 0) {  // no zero set found near p: the nearest sample bounds it
            uint32_t nearest = 0;
            float d2 = 0.0f;
            tree.nearest(glm::vec3(p), 1, &nearest, &d2);
            distance[i] = std::sqrt(double(d2)) * frame.size;
          } else {
            distance[i] = std::numeric_limits<double>::infinity();
          }
        }
      });
  TruthToIso out;
  out.distance.spacing = spacing;
  for (size_t i = 0; i < points.size(); ++i) {
    out.distance.add(distance[i], 1.0, points[i]);
    out.unprojected += projected[i] ? 0 : 1;
  }
  return out;
}

constexpr double kGrazing =
    0.3;  // cos 73°: rays this close to an open truth's tangent are not counted

struct Rays {
  uint64_t truthHits = 0, holes = 0, spurious = 0;
};

// Rays from a sphere around the truth. For a closed truth each ray aims at a point inside it
// (depth 1 % of the diagonal below a random surface point), so it must cross the surface before
// reaching that point whatever its angle: a ray that reaches it without hitting the zero set went
// through a hole. For an open truth each ray aims at a surface point and must hit the zero set
// near there.
Rays castRays(const SurfaceModel& surface, const Shape& truth, const EvalOptions& options) {
  const Frame& frame = surface.header().frame;
  const glm::dvec3 center = 0.5 * (truth.boundsMin() + truth.boundsMax());
  const double radius = glm::length(truth.boundsMax() - truth.boundsMin());
  const double depth = 0.01 * radius;
  std::vector<uint8_t> outcome(options.rays);  // bit 0: truth hit, bit 1: iso hit
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, outcome.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
        std::mt19937_64 rng(mixBits(options.seed * 0x100000001ull + r.begin()));
        for (size_t i = r.begin(); i < r.end(); ++i) {
          glm::dvec3 d(standardNormal(rng), standardNormal(rng), standardNormal(rng));
          const glm::dvec3 origin = center + radius * glm::normalize(d);
          // A closed truth's target lies at least half the depth from every part of the surface (a
          // point near an edge is deep below one face but close to the next), so it is inside the
          // zero set too, which is within a small fraction of the depth of the truth.
          SurfacePoint aim = truth.sample(rng);
          glm::dvec3 target = truth.isClosed() ? aim.position - depth * aim.normal : aim.position;
          for (int tries = 0;
               truth.isClosed() && truth.closest(target).distance < 0.5 * depth && tries < 100;
               ++tries) {
            aim = truth.sample(rng);
            target = aim.position - depth * aim.normal;
          }
          const double length = glm::length(target - origin);
          const glm::dvec3 direction = (target - origin) / length;
          // Past an open truth the zero set may be hit a little later: the allowance is the depth
          // over the cosine of incidence. Rays grazing an open truth (within 17° of its tangent
          // plane) are left out: there a miss is a silhouette a fraction of a spacing away, not a
          // hole.
          const double cosine = std::abs(glm::dot(direction, aim.normal));
          const double tMax = truth.isClosed() ? length : length + depth / std::max(cosine, 0.05);
          const bool grazing = !truth.isClosed() && cosine < kGrazing;
          const bool truthHit =
              !grazing && truth.intersect(origin, direction, 0.0, tMax).has_value();
          const glm::dvec3 o = toFrame(origin, frame), dir = direction / frame.size;
          const bool isoHit =
              surface.intersect({o.x, o.y, o.z}, {dir.x, dir.y, dir.z}, 0.0, tMax).has_value();
          outcome[i] = uint8_t((truthHit ? 1 : 0) | (isoHit ? 2 : 0));
        }
      });
  Rays rays;
  for (uint8_t o : outcome) {
    rays.truthHits += o & 1;
    rays.holes += (o & 1) && !(o & 2);
    rays.spurious += !(o & 1) && (o & 2);
  }
  return rays;
}

double outwardFraction(const std::vector<double>& anglesDeg) {
  if (anglesDeg.empty()) return 0.0;
  return double(
             std::count_if(anglesDeg.begin(), anglesDeg.end(), [](double a) { return a < 90.0; })) /
         double(anglesDeg.size());
}

nlohmann::json weightedJson(const Weighted& w, double spacing) {
  nlohmann::json out = {{"rms", w.rms()},
          {"max", w.max},
          {"mean", w.mean()},
          {"rms_over_spacing", w.rms() / spacing},
          {"max_over_spacing", w.max / spacing},
          {"beyond_half_spacing", w.share(w.beyondHalf)},
          {"beyond_two_spacings", w.share(w.beyondTwo)},
          {"bulk_rms_over_spacing", w.bulkRms() / spacing}};
  if (w.maxAt) out["max_at"] = {w.maxAt->x, w.maxAt->y, w.maxAt->z};
  return out;
}

// Both ways as one: RMS of the two RMS, the larger max, the mean shares, the RMS of the bulk RMS.
nlohmann::json bothWays(const Weighted& a, const Weighted& b, double spacing) {
  const auto rootMeanSquare = [](double x, double y) { return std::sqrt(0.5 * (x * x + y * y)); };
  const double rms = rootMeanSquare(a.rms(), b.rms()), max = std::max(a.max, b.max);
  return {{"rms", rms},
          {"max", max},
          {"mean", 0.5 * (a.mean() + b.mean())},
          {"spacing", spacing},
          {"rms_over_spacing", rms / spacing},
          {"max_over_spacing", max / spacing},
          {"beyond_half_spacing", 0.5 * (a.share(a.beyondHalf) + b.share(b.beyondHalf))},
          {"beyond_two_spacings", 0.5 * (a.share(a.beyondTwo) + b.share(b.beyondTwo))},
          {"bulk_rms_over_spacing", rootMeanSquare(a.bulkRms(), b.bulkRms()) / spacing}};
}

}  // namespace

nlohmann::json evaluateAgainstShape(const SurfaceModel& surface, const Shape& truth,
                                    double pointSpacing, const EvalOptions& options) {
  const IsoToTruth a = isoToTruth(surface, truth, options, pointSpacing);
  const TruthToIso b = truthToIso(surface, truth, a.samples, options, pointSpacing);
  const Rays rays = castRays(surface, truth, options);
  const double diagonal = glm::length(truth.boundsMax() - truth.boundsMin());
  nlohmann::json iso = weightedJson(a.distance, pointSpacing);
  iso["samples"] = a.normalAngles.size();
  nlohmann::json back = weightedJson(b.distance, pointSpacing);
  back["samples"] = options.truthSamples;
  back["unprojected"] = b.unprojected;
  nlohmann::json out = bothWays(a.distance, b.distance, pointSpacing);
  out["truth"] = truth.name();
  out.update(nlohmann::json{
          {"rms_over_diagonal", out["rms"].get<double>() / diagonal},
          {"normal_median_deg", percentile(a.normalAngles, 0.5)},
          {"normal_p99_deg", percentile(a.normalAngles, 0.99)},
          {"normal_outward_fraction", outwardFraction(a.normalAngles)},
          {"hole_rate", rays.truthHits > 0 ? double(rays.holes) / double(rays.truthHits) : 0.0},
          {"rays", options.rays},
          {"rays_hitting_truth", rays.truthHits},
          {"holes", rays.holes},
          {"spurious_hits", rays.spurious},
          {"iso_to_truth", iso},
          {"truth_to_iso", back}});
  return out;
}

namespace {

struct ColorError {
  uint64_t points = 0;   // points compared
  double squared = 0.0;  // sum over points and channels of the squared 8-bit sRGB differences
};

// Each colored point against the surface's color where the point projects onto the zero set
// (`projected`, frame units), both sRGB-encoded on the 0–255 scale.
ColorError colorError(const SurfaceModel& surface, const PointCloud& points,
                      const std::vector<std::optional<Vec3>>& projected) {
  std::vector<double> squared(points.size(), -1.0);
  tbb::parallel_for(size_t(0), points.size(), [&](size_t i) {
    const std::optional<Vec3>& q = projected[i];
    if (!q) return;
    const uint32_t leaf = surface.findLeaf(*q);
    if (leaf == kNoNode) return;
    const SurfaceEval e = surface.evaluate(leaf, *q);
    double sum = 0.0;
    for (int c = 0; c < 3; ++c) {
      const double d = 255.0 * (double(linearToSrgb(std::clamp(e.color[c], 0.0f, 1.0f))) -
                                linearToSrgb(std::clamp(points.colors[i][c], 0.0f, 1.0f)));
      sum += d * d;
    }
    squared[i] = sum;
  });
  ColorError out;
  for (double v : squared)
    if (v >= 0.0) {
      ++out.points;
      out.squared += v;
    }
  return out;
}

}  // namespace

nlohmann::json evaluateAgainstPoints(const SurfaceModel& surface, const PointCloud& points) {
  return evaluateAgainstPoints(surface, points, pointSpacing(points));
}

nlohmann::json evaluateAgainstPoints(const SurfaceModel& surface, const PointCloud& points,
                                     double spacing) {
  const bool colors = points.hasColors() && surface.hasColors();
  std::vector<std::optional<Vec3>> projected;
  const DistanceStats d = pointsToZeroSet(surface, surface.header().frame, points.positions, false,
                                          colors ? &projected : nullptr);
  nlohmann::json color = nullptr;
  if (colors) {
    const ColorError e = colorError(surface, points, projected);
    const double mse = e.points > 0 ? e.squared / (3.0 * double(e.points)) : 0.0;
    color = {{"points", e.points},
             {"rmse_8bit", std::sqrt(mse)},
             // Peak signal 255 over the root mean square error of the 8-bit sRGB channels; none
             // (null) when they are equal everywhere.
             {"psnr_db", mse > 0 ? nlohmann::json(10.0 * std::log10(255.0 * 255.0 / mse))
                                 : nlohmann::json(nullptr)}};
  }
  return {{"points", d.samples},
          {"color_psnr_db", color.is_null() ? nlohmann::json(nullptr) : color["psnr_db"]},
          {"color", color},
          {"unprojected", d.unprojected},
          {"rms", d.rms},
          {"max", d.max},
          {"mean", d.mean},
          {"spacing", spacing},
          {"rms_over_spacing", spacing > 0 ? d.rms / spacing : 0.0},
          {"max_over_spacing", spacing > 0 ? d.max / spacing : 0.0}};
}

nlohmann::json evaluateLevels(const Reader& reader, const PointCloud& points) {
  const double spacing = pointSpacing(points);
  // Chunks decoded once for all the cuts.
  std::map<uint32_t, std::shared_ptr<const SurfaceChunk>> decoded;
  const SurfaceModel::ChunkSource source = [&](uint32_t id) {
    auto& chunk = decoded[id];
    if (!chunk) chunk = std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader, id));
    return chunk;
  };
  uint8_t first = kMaxLevel, last = 0;
  for (const ChunkInfo& info : reader.chunks()) {
    if (info.kind != kSurfaceKind) continue;
    const std::shared_ptr<const SurfaceChunk> chunk = source(info.id);
    first = std::min(first, chunk->topology.startLevel);
    last = std::max(last, uint8_t(chunk->topology.startLevel + chunk->topology.depth - 1));
  }
  nlohmann::json levels = nlohmann::json::array();
  for (int level = first; level <= last; ++level) {
    const SurfaceModel cut = SurfaceModel::load(reader, {}, source, uint8_t(level));
    nlohmann::json e = evaluateAgainstPoints(cut, points, spacing);
    e["level"] = level;
    e["patches"] = cut.leaves().size();
    levels.push_back(std::move(e));
  }
  return levels;
}

namespace {

struct OneWay {
  nlohmann::json json;
  ColorError color;
};

// Area-weighted samples of `from`'s zero set projected onto `onto`.
OneWay oneWay(const SurfaceModel& from, const SurfaceModel& onto, int linesPerEdge, bool colors) {
  const std::vector<ZeroSetSample> samples = from.sampleZeroSet(linesPerEdge);
  const Frame& f = from.header().frame;
  std::vector<glm::dvec3> world(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) world[i] = toWorld(samples[i].position, f);
  std::vector<std::optional<Vec3>> projected;
  const DistanceStats d = pointsToZeroSet(onto, onto.header().frame, world, true, &projected);
  // Weighted by the area each sample stands for; `values` follow the projected samples in order.
  double sum = 0.0, area = 0.0;
  size_t k = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    if (!projected[i]) continue;
    const double v = d.values[k++];
    sum += samples[i].area * v * v;
    area += samples[i].area;
  }
  OneWay out;
  out.json = {{"samples", d.samples},
              {"unprojected", d.unprojected},
              {"rms", area > 0.0 ? std::sqrt(sum / area) : 0.0},
              {"max", d.max},
              {"mean", d.mean}};
  if (colors) {
    PointCloud points;  // the samples with from's colors, for colorError
    points.positions = world;
    points.colors.resize(samples.size());
    for (size_t i = 0; i < samples.size(); ++i)
      points.colors[i] = [&] {
        const SurfaceEval e = from.evaluate(samples[i].leaf, samples[i].position);
        return glm::vec3(e.color[0], e.color[1], e.color[2]);
      }();
    out.color = colorError(onto, points, projected);
  }
  return out;
}

}  // namespace

nlohmann::json evaluateAgainstFile(const SurfaceModel& a, const SurfaceModel& b, int linesPerEdge) {
  const bool colors = a.hasColors() && b.hasColors();
  const OneWay ab = oneWay(a, b, linesPerEdge, colors), ba = oneWay(b, a, linesPerEdge, false);
  const double rmsAB = ab.json["rms"].get<double>(), rmsBA = ba.json["rms"].get<double>();
  nlohmann::json out = {
      {"rms", std::sqrt(0.5 * (rmsAB * rmsAB + rmsBA * rmsBA))},
      {"max", std::max(ab.json["max"].get<double>(), ba.json["max"].get<double>())},
      {"a_to_b", ab.json},
      {"b_to_a", ba.json},
      {"color_psnr_db", nullptr}};
  if (colors && ab.color.points > 0) {
    const double mse = ab.color.squared / (3.0 * double(ab.color.points));
    out["color_psnr_db"] =
        mse > 0 ? nlohmann::json(10.0 * std::log10(255.0 * 255.0 / mse)) : nlohmann::json(nullptr);
  }
  return out;
}

namespace {

// The distance from each of `count` points (drawn by `point(rng, i)`, in parallel with one stream
// per block) to `distance(p)`, tallied.
template <typename Point, typename Distance>
Weighted tallyDistances(uint64_t count, uint64_t seed, double spacing, Point point,
                        Distance distance) {
  constexpr uint64_t kBlock = 4096;
  std::vector<double> d(count);
  tbb::parallel_for(uint64_t{0}, (count + kBlock - 1) / kBlock, [&](uint64_t block) {
    std::mt19937_64 rng(seed + block);
    for (uint64_t i = block * kBlock; i < std::min(count, (block + 1) * kBlock); ++i)
      d[i] = distance(point(rng, i));
  });
  Weighted w;
  w.spacing = spacing;
  for (double v : d) w.add(v, 1.0);
  return w;
}

nlohmann::json meshJson(const Weighted& meshToTruth, const Weighted& truthToMesh, double spacing,
                        const TriangleMesh& mesh) {
  nlohmann::json out = bothWays(meshToTruth, truthToMesh, spacing);
  out["mesh_to_truth"] = weightedJson(meshToTruth, spacing);
  out["truth_to_mesh"] = weightedJson(truthToMesh, spacing);
  out["triangles"] = mesh.triangles.size();
  return out;
}

}  // namespace

nlohmann::json evaluateMeshAgainstShape(const TriangleMesh& mesh, const Shape& truth,
                                        double pointSpacing, uint64_t samples, uint64_t seed) {
  const std::unique_ptr<Shape> surface = makeMeshShape(mesh);
  const auto oneWay = [&](const Shape& from, const Shape& to, uint64_t salt) {
    return tallyDistances(
        samples, seed * 0x9e3779b97f4a7c15ull + salt, pointSpacing,
        [&](std::mt19937_64& rng, uint64_t) { return from.sample(rng).position; },
        [&](const glm::dvec3& p) { return to.closest(p).distance; });
  };
  nlohmann::json out = meshJson(oneWay(*surface, truth, 1), oneWay(truth, *surface, 2),
                                pointSpacing, mesh);
  out["samples"] = samples;
  return out;
}

nlohmann::json evaluateMeshAgainstPoints(const TriangleMesh& mesh, const PointCloud& points,
                                         double pointSpacing, uint64_t samples, uint64_t seed) {
  ISO_CHECK(!points.positions.empty());
  const std::unique_ptr<Shape> surface = makeMeshShape(mesh);
  // The points relative to their first, in float, for the nearest-point index.
  const glm::dvec3 origin = points.positions[0];
  std::vector<glm::vec3> local(points.positions.size());
  for (size_t i = 0; i < local.size(); ++i) local[i] = glm::vec3(points.positions[i] - origin);
  const PointIndex index(local);
  const Weighted meshToPoints = tallyDistances(
      samples, seed * 0x9e3779b97f4a7c15ull + 1, pointSpacing,
      [&](std::mt19937_64& rng, uint64_t) { return surface->sample(rng).position; },
      [&](const glm::dvec3& p) {
        uint32_t nearest = 0;
        float d2 = 0.0f;
        index.nearest(glm::vec3(p - origin), 1, &nearest, &d2);
        return glm::length(points.positions[nearest] - p);
      });
  const uint64_t step = std::max<uint64_t>(1, points.size() / samples);
  const Weighted pointsToMesh = tallyDistances(
      (points.size() + step - 1) / step, seed, pointSpacing,
      [&](std::mt19937_64&, uint64_t i) { return points.positions[i * step]; },
      [&](const glm::dvec3& p) { return surface->closest(p).distance; });
  nlohmann::json out = meshJson(meshToPoints, pointsToMesh, pointSpacing, mesh);
  out["samples"] = samples;
  return out;
}

}  // namespace iso
