// The ISO surface against the point set surface of its points (against_pss.h).
#include "pipeline/analysis/against_pss.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/geometric.hpp>
#include <optional>

#include "iso/check.h"
#include "pipeline/points/viewing.h"
#include "tracer/cpu_tracer.h"
#include "tracer/pss.h"

namespace iso {
namespace {

using Clock = std::chrono::steady_clock;
double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// One shading for both pictures: a headlight, Lambert, as 8-bit gray (background 0).
double shade(const glm::vec3& normal, const glm::vec3& d) {
  return std::round(255.0 * (0.15 + 0.85 * std::abs(glm::dot(normal, d))));
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[size_t(q * double(v.size() - 1))];
}

}  // namespace

nlohmann::json evaluateAgainstPss(const Reader& reader, PointCloud points, double spacing,
                                  const AgainstPssOptions& options) {
  ISO_CHECK(points.size() > 0);
  glm::dvec3 lo = points.positions[0], hi = lo;
  for (const glm::dvec3& p : points.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::dvec3 center = 0.5 * (lo + hi);
  const double radius = 0.5 * glm::length(hi - lo);
  const auto t0 = Clock::now();
  const size_t count = points.size();
  ViewingPoints v = prepareForViewing(std::move(points), center, float(spacing));
  std::vector<float> h(v.spacings.size());
  for (size_t i = 0; i < h.size(); ++i) h[i] = 2.0f * v.spacings[i];
  const viewer::PssSurface pss(std::move(v.positions), std::move(v.normals), std::move(h));
  const double fit = seconds(Clock::now() - t0);
  const viewer::CpuPool pool = viewer::buildCpuPool(reader);
  const auto params = viewer::finestFrameParams(pool);
  const Frame& frame = reader.header().frame;
  const glm::dvec3 frameOrigin(frame.origin[0], frame.origin[1], frame.origin[2]);

  const int n = options.size;
  const double tanHalf = std::tan(20.0 * M_PI / 180.0);
  const double distance = radius / std::sin(20.0 * M_PI / 180.0) * 1.05;
  std::vector<double> depths, angles;
  size_t both = 0, either = 0, within = 0;
  double squared = 0.0, squaredBoth = 0.0, isoSeconds = 0.0, pssSeconds = 0.0;
  uint64_t rays = 0;
  const glm::dvec3 axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (const glm::dvec3& axis : axes) {
    const glm::dvec3 eye = center + distance * axis, f = -axis;
    const glm::dvec3 up = std::abs(axis.y) > 0.5 ? glm::dvec3(0, 0, 1) : glm::dvec3(0, 1, 0);
    const glm::dvec3 r = glm::normalize(glm::cross(f, up)), u = glm::cross(r, f);
    std::vector<glm::vec3> dirs(size_t(n) * n);
    std::vector<viewer::CpuRay> isoRays(dirs.size());
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const glm::dvec3 d = glm::normalize(f + ((x + 0.5) / n * 2 - 1) * tanHalf * r +
                                            (1 - (y + 0.5) / n * 2) * tanHalf * u);
        dirs[size_t(y) * n + x] = glm::vec3(d);
        isoRays[size_t(y) * n + x] = {glm::vec3((eye - frameOrigin) / frame.size), glm::vec3(d)};
      }
    std::vector<std::optional<viewer::CpuHit>> isoHits(dirs.size());
    auto t = Clock::now();
    viewer::traceCpu(pool, params, isoRays, isoHits);
    isoSeconds += seconds(Clock::now() - t);
    std::vector<std::optional<viewer::PssHit>> pssHits(dirs.size());
    const glm::vec3 origin(eye - center);
    t = Clock::now();
    tbb::parallel_for(size_t{0}, dirs.size(), [&](size_t i) {
      viewer::PssHit hit;
      if (pss.intersect(origin, dirs[i], 0.0f, 1e30f, viewer::PssMode::Exact, hit))
        pssHits[i] = hit;
    });
    pssSeconds += seconds(Clock::now() - t);
    rays += dirs.size();
    std::vector<uint8_t> isoPicture(dirs.size()), pssPicture(dirs.size());
    for (size_t i = 0; i < dirs.size(); ++i) {
      const auto& a = isoHits[i];
      const auto& b = pssHits[i];
      const double pa = a ? shade(a->normal, dirs[i]) : 0.0, pb = b ? shade(b->normal, dirs[i]) : 0.0;
      isoPicture[i] = uint8_t(pa);
      pssPicture[i] = uint8_t(pb);
      squared += (pa - pb) * (pa - pb);
      either += a || b;
      if (!a || !b) continue;
      ++both;
      squaredBoth += (pa - pb) * (pa - pb);
      const double depth = std::abs(double(a->t) * frame.size - double(b->t)) / spacing;
      depths.push_back(depth);
      within += depth <= 1.0;
      const double c = std::clamp(std::abs(double(glm::dot(a->normal, b->normal))), 0.0, 1.0);
      angles.push_back(std::acos(c) * 180.0 / M_PI);
    }
    if (options.pictures) options.pictures(int(&axis - axes), isoPicture, pssPicture);
  }
  const double mse = squared / double(rays);
  nlohmann::json out;
  out["views"] = 6;
  out["size"] = n;
  out["points"] = count;
  out["spacing"] = spacing;
  out["pss_fit_seconds"] = fit;
  out["silhouette_iou"] = either ? double(both) / double(either) : 0.0;
  out["depth_spacings"] = {{"median", quantile(depths, 0.5)},
                           {"p95", quantile(depths, 0.95)},
                           {"max", quantile(depths, 1.0)},
                           {"within_one", both ? double(within) / double(both) : 0.0}};
  out["normal_degrees"] = {{"median", quantile(angles, 0.5)}, {"p95", quantile(angles, 0.95)}};
  out["psnr_db"] = mse > 0.0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;
  // Where the difference is: the pixels both cover (shading), the others (silhouettes).
  const double mseBoth = both ? squaredBoth / double(both) : 0.0;
  out["psnr_where_both_hit_db"] = mseBoth > 0.0 ? 10.0 * std::log10(255.0 * 255.0 / mseBoth) : 99.0;
  out["silhouette_share_of_error"] = squared > 0.0 ? 1.0 - squaredBoth / squared : 0.0;
  out["shading"] = "a headlight, Lambert, 8-bit gray, on both";
  out["iso_rays_per_second"] = double(rays) / isoSeconds;
  out["pss_exact_rays_per_second"] = double(rays) / pssSeconds;
  out["iso_over_pss_speed"] = pssSeconds / isoSeconds;
  return out;
}

}  // namespace iso
