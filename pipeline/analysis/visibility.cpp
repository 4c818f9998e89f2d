// The visibility measure (pipeline/analysis/visibility.h, specs/pipeline.md §18).
#include "pipeline/analysis/visibility.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <map>
#include <optional>
#include <random>

#include "iso/check.h"
#include "iso/reader.h"
#include "pipeline/points/points.h"
#include "tracer/cpu_tracer.h"

namespace iso {
namespace {

// An orthographic view: the direction d, the image plane's axes e1 and e2, and the depth (along
// d) of the plane the rays start from, in front of the whole frame cube.
struct View {
  glm::dvec3 d{}, e1{}, e2{};
  double start = 0.0;

  explicit View(const glm::dvec3& direction) : d(glm::normalize(direction)) {
    const glm::dvec3 a = std::abs(d.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    e1 = glm::normalize(glm::cross(d, a));
    e2 = glm::cross(d, e1);
    for (int c = 0; c < 8; ++c)
      start = std::min(start, glm::dot(glm::dvec3(c & 1, c >> 1 & 1, c >> 2 & 1), d));
    start -= 1e-3;
  }
  // The ray along d through the image-plane point (x, y), clipped to the box [lo, hi].
  viewer::CpuRay ray(double x, double y, const glm::dvec3& lo, const glm::dvec3& hi) const {
    const glm::dvec3 o = x * e1 + y * e2 + start * d;
    double t0 = 0.0, t1 = 1e30;
    for (int k = 0; k < 3; ++k) {
      if (d[k] == 0.0) {
        if (o[k] < lo[k] || o[k] > hi[k]) t1 = -1.0;
        continue;
      }
      const double a = (lo[k] - o[k]) / d[k], b = (hi[k] - o[k]) / d[k];
      t0 = std::max(t0, std::min(a, b));
      t1 = std::min(t1, std::max(a, b));
    }
    return {glm::vec3(o), glm::vec3(d), float(t0), float(t1)};
  }
};

// The part of the frame a measure traces in: rays are clipped to it.
struct Box {
  glm::dvec3 lo{-1.0}, hi{2.0};
};

// The depth error looks for the surface this many spacings before and after each point.
constexpr double kDepthWindow = 3.0;

// A pixel (ix, iy) as one sortable key.
uint64_t pixelKey(int64_t ix, int64_t iy) {
  return uint64_t(ix + (int64_t(1) << 31)) << 32 | uint64_t(uint32_t(iy + (int64_t(1) << 31)));
}
int64_t pixelX(uint64_t key) { return int64_t(key >> 32) - (int64_t(1) << 31); }
int64_t pixelY(uint64_t key) { return int64_t(key & 0xFFFFFFFFu) - (int64_t(1) << 31); }
uint64_t shifted(uint64_t key, int dx, int dy) {
  return pixelKey(pixelX(key) + dx, pixelY(key) + dy);
}

// A sorted set of pixel keys with a value each.
template <typename T>
struct PixelMap {
  std::vector<uint64_t> keys;
  std::vector<T> values;
  const T* find(uint64_t key) const {
    const auto it = std::lower_bound(keys.begin(), keys.end(), key);
    return it != keys.end() && *it == key ? &values[size_t(it - keys.begin())] : nullptr;
  }
};

// Whether the rays through the centres of pixels hit the surface, traced on demand.
class PixelHits {
 public:
  PixelHits(const viewer::CpuPool& pool, const gpu::FrameParams& params, const View& view,
            const Box& box, double pixel, uint64_t& rays)
      : pool_(pool), params_(params), view_(view), box_(box), pixel_(pixel), rays_(rays) {}

  // Trace the pixels of `keys` not traced yet.
  void trace(std::vector<uint64_t> keys) {
    tbb::parallel_sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    std::vector<uint64_t> fresh;
    std::set_difference(keys.begin(), keys.end(), hits_.keys.begin(), hits_.keys.end(),
                        std::back_inserter(fresh));
    std::vector<viewer::CpuRay> rays(fresh.size());
    for (size_t i = 0; i < fresh.size(); ++i)
      rays[i] = view_.ray((double(pixelX(fresh[i])) + 0.5) * pixel_,
                          (double(pixelY(fresh[i])) + 0.5) * pixel_, box_.lo, box_.hi);
    std::vector<std::optional<viewer::CpuHit>> hits(fresh.size());
    viewer::traceCpu(pool_, params_, rays, hits);
    rays_ += rays.size();
    PixelMap<uint8_t> merged;
    merged.keys.reserve(hits_.keys.size() + fresh.size());
    merged.values.reserve(hits_.keys.size() + fresh.size());
    size_t a = 0, b = 0;
    while (a < hits_.keys.size() || b < fresh.size()) {
      if (b == fresh.size() || (a < hits_.keys.size() && hits_.keys[a] < fresh[b])) {
        merged.keys.push_back(hits_.keys[a]);
        merged.values.push_back(hits_.values[a++]);
      } else {
        merged.keys.push_back(fresh[b]);
        merged.values.push_back(hits[b++].has_value());
      }
    }
    hits_ = std::move(merged);
  }

  bool hit(uint64_t key) const {
    const uint8_t* h = hits_.find(key);
    ISO_CHECK(h != nullptr);
    return *h != 0;
  }

 private:
  const viewer::CpuPool& pool_;
  const gpu::FrameParams& params_;
  const View& view_;
  const Box& box_;
  double pixel_;
  uint64_t& rays_;
  PixelMap<uint8_t> hits_;
};

// The q-quantile of values (reordered), 0 for none.
double quantile(std::vector<double>& values, double q) {
  if (values.empty()) return 0.0;
  const size_t k = std::min(values.size() - 1, size_t(q * double(values.size())));
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
  return values[k];
}

struct Projected {
  uint64_t key;  // pixel
  double depth;  // along the view
  uint32_t index;
};

// The points' pixels and depths, sorted by pixel, then depth.
std::vector<Projected> project(std::span<const glm::dvec3> points, const View& view, double pixel) {
  std::vector<Projected> out(points.size());
  tbb::parallel_for(size_t(0), points.size(), [&](size_t i) {
    const glm::dvec3& p = points[i];
    out[i] = {pixelKey(int64_t(std::floor(glm::dot(p, view.e1) / pixel)),
                       int64_t(std::floor(glm::dot(p, view.e2) / pixel))),
              glm::dot(p, view.d), uint32_t(i)};
  });
  tbb::parallel_sort(out.begin(), out.end(), [](const Projected& a, const Projected& b) {
    return a.key != b.key       ? a.key < b.key
           : a.depth != b.depth ? a.depth < b.depth
                                : a.index < b.index;
  });
  return out;
}

// The depth of the nearest point of each pixel that holds points.
PixelMap<double> nearestDepths(const std::vector<Projected>& projected) {
  PixelMap<double> nearest;
  for (size_t i = 0; i < projected.size(); ++i)
    if (i == 0 || projected[i - 1].key != projected[i].key) {
      nearest.keys.push_back(projected[i].key);
      nearest.values.push_back(projected[i].depth);
    }
  return nearest;
}

// What one view saw of the points, summed over regions.
struct Tally {
  ViewVisibility view;
  std::vector<double> errors;  // the points' depth errors, in spacings
};

// Whether each point lies inside the outline of the points' own image in a view: the 3×3 blocks
// of two-spacing cells around it all hold points (two spacings, so that a surface sampled about
// once a spacing leaves none empty by chance). Computed on all the points, whatever the regions.
std::vector<uint8_t> insideOutline(std::span<const glm::dvec3> points, const View& view,
                                   double spacing) {
  const std::vector<Projected> projected = project(points, view, 2.0 * spacing);
  const PixelMap<double> occupied = nearestDepths(projected);
  std::vector<uint8_t> inside(points.size(), 0);
  tbb::parallel_for(size_t(0), projected.size(), [&](size_t i) {
    bool all = true;
    for (int dy = -1; dy <= 1 && all; ++dy)
      for (int dx = -1; dx <= 1 && all; ++dx)
        all = occupied.find(shifted(projected[i].key, dx, dy)) != nullptr;
    inside[projected[i].index] = all;
  });
  return inside;
}

// One view of the points of a region (frame units; `index` maps them to the measured points,
// `inside` flags those inside the outline): seen-through points appended to `seen`, counts and
// depth errors added to the tally.
void measureView(const viewer::CpuPool& pool, const gpu::FrameParams& params,
                 std::span<const glm::dvec3> points, std::span<const uint32_t> index,
                 const std::vector<uint8_t>& inside, const Box& box, double spacing, double pixel,
                 const View& view, Tally& tally, std::vector<uint32_t>& seen, uint64_t& rays) {
  ViewVisibility& out = tally.view;
  out.points += points.size();
  const std::vector<Projected> projected = project(points, view, pixel);
  const PixelMap<double> pixels = nearestDepths(projected);
  // Every pixel that holds points, then the 8 neighbours of those that missed.
  PixelHits hits(pool, params, view, box, pixel, rays);
  hits.trace(pixels.keys);
  std::vector<uint64_t> around;
  for (const uint64_t key : pixels.keys)
    if (!hits.hit(key))
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) around.push_back(shifted(key, dx, dy));
  hits.trace(std::move(around));
  std::vector<viewer::CpuRay> exact(projected.size());
  for (size_t i = 0; i < projected.size(); ++i) {
    const Projected& q = projected[i];
    bool shown = hits.hit(q.key);
    for (int dy = -1; dy <= 1 && !shown; ++dy)
      for (int dx = -1; dx <= 1 && !shown; ++dx) shown = hits.hit(shifted(q.key, dx, dy));
    if (!shown) {
      ++out.seenThrough;
      out.seenThroughInside += inside[index[q.index]];
      seen.push_back(index[q.index]);
    }
    // The ray through the point itself, from kDepthWindow spacings before it to as far after.
    const glm::dvec3& p = points[q.index];
    exact[i] = view.ray(glm::dot(p, view.e1), glm::dot(p, view.e2), box.lo, box.hi);
    const double before = q.depth - view.start - kDepthWindow * spacing;
    exact[i].tMin = std::max(exact[i].tMin, float(before));
    exact[i].tMax = std::min(exact[i].tMax, float(before + 2.0 * kDepthWindow * spacing));
  }
  std::vector<std::optional<viewer::CpuHit>> exactHits(exact.size());
  viewer::traceCpu(pool, params, exact, exactHits);
  rays += exact.size();
  for (size_t i = 0; i < exact.size(); ++i) {
    if (!exactHits[i]) {
      ++out.depthMissed;
      continue;
    }
    ++out.depthMeasured;
    tally.errors.push_back(std::abs(view.start + double(exactHits[i]->t) - projected[i].depth) /
                           spacing);
  }
}

// The level whose cells are the regions: a surface meets about 4^level cells of a level, so that
// a region holds about regionLeaves leaves.
uint8_t regionLevel(const Reader& reader, uint64_t regionLeaves) {
  uint64_t leaves = 0;
  for (const ChunkInfo& info : reader.chunks()) leaves += info.leafCount;
  uint8_t level = 0;
  while (level < 7 && (uint64_t{1} << (2 * level)) * std::max<uint64_t>(regionLeaves, 1) < leaves)
    ++level;
  return level;
}

}  // namespace

std::vector<glm::dvec3> visibilityViews(int random, uint64_t seed) {
  std::vector<glm::dvec3> views = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                   {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  for (int i = 0; i < random; ++i) {
    glm::dvec3 d;
    do {
      d = {normal(rng), normal(rng), normal(rng)};
    } while (!(glm::length(d) > 1e-6));
    views.push_back(glm::normalize(d));
  }
  return views;
}

Visibility measureVisibility(const Reader& reader, std::span<const glm::dvec3> points,
                             double pointSpacing, const VisibilityOptions& options) {
  ISO_CHECK(pointSpacing > 0.0 && options.pixelSpacings > 0.0);
  const Frame& frame = reader.header().frame;
  Visibility out;
  out.pixelSpacings = options.pixelSpacings;
  // The points inside the frame, by region (cells of one level, in key order).
  const uint8_t level = regionLevel(reader, options.regionLeaves);
  std::map<uint64_t, std::vector<uint32_t>> regions;
  std::vector<glm::dvec3> inFrame;
  const glm::dvec3 origin(frame.origin[0], frame.origin[1], frame.origin[2]);
  for (uint32_t i = 0; i < points.size(); ++i) {
    const glm::dvec3 q = (points[i] - origin) / frame.size;
    if (!(q.x >= 0.0 && q.x < 1.0 && q.y >= 0.0 && q.y < 1.0 && q.z >= 0.0 && q.z < 1.0)) continue;
    regions[keyOf(glm::vec3(q)) >> (3 * (kMaxLevel - level))].push_back(uint32_t(inFrame.size()));
    out.measured.push_back(i);
    inFrame.push_back(q);
  }
  const double spacing = pointSpacing / frame.size, pixel = options.pixelSpacings * spacing;
  const std::vector<glm::dvec3> directions = visibilityViews(options.randomViews, options.seed);
  std::vector<Tally> tallies(directions.size());
  std::vector<std::vector<uint8_t>> inside;
  for (const glm::dvec3& d : directions) inside.push_back(insideOutline(inFrame, View(d), spacing));
  std::vector<uint32_t> seen;
  const double edge = std::ldexp(1.0, -level), margin = level == 0 ? 1.0 : edge / 16.0;
  for (const auto& [key, which] : regions) {
    // The region's cell widened by a margin; the chunks that meet it; rays clipped to it.
    const auto cell = mortonDecode(key);
    Box box;
    for (int a = 0; a < 3; ++a) {
      box.lo[a] = double(cell[size_t(a)]) * edge - margin;
      box.hi[a] = double(cell[size_t(a)] + 1) * edge + margin;
    }
    const viewer::CpuPool pool = viewer::buildCpuPool(reader, [&](const ChunkInfo& c) {
      const auto at = mortonDecode(c.key);
      const double size = std::ldexp(1.0, -int(c.level));
      for (int a = 0; a < 3; ++a)
        if (double(at[size_t(a)]) * size > box.hi[a] ||
            double(at[size_t(a)] + 1) * size < box.lo[a])
          return false;
      return true;
    });
    const gpu::FrameParams params = viewer::finestFrameParams(pool);
    std::vector<glm::dvec3> regionPoints(which.size());
    for (size_t j = 0; j < which.size(); ++j) regionPoints[j] = inFrame[which[j]];
    for (size_t v = 0; v < directions.size(); ++v)
      measureView(pool, params, regionPoints, which, inside[v], box, spacing, pixel,
                  View(directions[v]), tallies[v], seen, out.rays);
  }
  std::vector<double> depths;
  for (size_t v = 0; v < directions.size(); ++v) {
    Tally& t = tallies[v];
    t.view.direction = glm::normalize(directions[v]);
    t.view.depthMax = t.errors.empty() ? 0.0 : *std::max_element(t.errors.begin(), t.errors.end());
    depths.insert(depths.end(), t.errors.begin(), t.errors.end());
    t.view.depthP90 = quantile(t.errors, 0.9);
    t.view.depthMedian = quantile(t.errors, 0.5);
    out.views.push_back(t.view);
  }
  // Seen-through points as indices into `points`, each once.
  std::sort(seen.begin(), seen.end());
  seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
  for (uint32_t& i : seen) i = out.measured[i];
  out.seen = std::move(seen);
  out.depthP90 = quantile(depths, 0.9);
  out.depthMedian = quantile(depths, 0.5);
  return out;
}

double Visibility::seenThroughFraction() const {
  uint64_t seenCount = 0, all = 0;
  for (const ViewVisibility& v : views) {
    seenCount += v.seenThrough;
    all += v.points;
  }
  return all ? double(seenCount) / double(all) : 0.0;
}

double Visibility::worstViewFraction() const {
  double worst = 0.0;
  for (const ViewVisibility& v : views) worst = std::max(worst, v.seenThroughFraction());
  return worst;
}

nlohmann::json Visibility::json() const {
  nlohmann::json perView = nlohmann::json::array();
  uint64_t seenCount = 0, inside = 0;
  for (const ViewVisibility& v : views) {
    seenCount += v.seenThrough;
    inside += v.seenThroughInside;
    perView.push_back({{"direction", {v.direction.x, v.direction.y, v.direction.z}},
                       {"seen_through", v.seenThrough},
                       {"seen_through_fraction", v.seenThroughFraction()},
                       {"seen_through_inside", v.seenThroughInside},
                       {"depth_measured", v.depthMeasured},
                       {"depth_missed", v.depthMissed},
                       {"depth_error_median", v.depthMedian},
                       {"depth_error_p90", v.depthP90},
                       {"depth_error_max", v.depthMax}});
  }
  return {{"points", measured.size()},
          {"views", views.size()},
          {"pixel_spacings", pixelSpacings},
          {"rays", rays},
          {"seen_through", seenCount},
          {"seen_through_inside", inside},
          {"seen_through_fraction", seenThroughFraction()},
          {"worst_view_fraction", worstViewFraction()},
          {"depth_error_median", depthMedian},
          {"depth_error_p90", depthP90},
          {"per_view", perView}};
}

}  // namespace iso
