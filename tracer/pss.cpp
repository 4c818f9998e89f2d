// Point set surfaces on the CPU (pss.h): shaders/pss.h's intersection, the fits, the grid.
#include "tracer/pss.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <limits>

#include "iso/check.h"
#include "iso/error.h"

namespace iso::viewer {
namespace pss_shader {

using namespace glm;
#define ISO_INOUT(T) T&

// The GLSL environment of shaders/pss.h: the surface's grid, points and patches in host memory.
class Env {
 public:
  Env(const PssSurface::Grid& grid, const std::vector<vec3>& positions,
      const std::vector<vec3>& normals, const std::vector<float>& h,
      const std::vector<PssPatch>& patches, const PssOptions& o)
      : grid_(grid), positions_(positions), normals_(normals), h_(h), patches_(patches),
        settings_(o.trust, o.reach, o.tolerance, float(o.maxProjections)) {}

  vec3 pssGridLo() const { return grid_.lo; }
  float pssGridSide() const { return grid_.side; }
  ivec3 pssGridDims() const { return grid_.dims; }
  uint pssPointStart(uint c) const { return grid_.pointStart[c]; }
  uint pssPointAt(uint k) const { return grid_.points[k]; }
  uint pssReachStart(uint c) const { return grid_.reachStart[c]; }
  uint pssReachAt(uint k) const { return grid_.reach[k]; }
  vec3 pssPosition(uint i) const { return positions_[i]; }
  vec3 pssNormal(uint i) const { return normals_[i]; }
  float pssH(uint i) const { return h_[i]; }
  vec4 pssPatch(uint i, int part) const {
    const PssPatch& p = patches_[i];
    return part == 0 ? p.origin : part == 1 ? p.normal : part == 2 ? p.tangent : p.coefficients;
  }
  vec4 pssSettings() const { return settings_; }

  // Ray tracing (pss_trace.h): set when a picture is drawn.
  const PssRender* render = nullptr;
  const std::vector<vec3>* colors = nullptr;
  uint pssLightCount() const { return uint(render->lights.size()); }
  vec4 pssLight(uint l) const {
    return vec4(render->lights[l].position, render->lights[l].intensity);
  }
  vec4 pssMaterial() const { return render->material; }
  float pssReflectivity() const { return render->reflectivity; }
  vec4 pssIors() const { return vec4(render->iors, render->ambient); }
  vec3 pssColor(uint point) const { return colors->empty() ? render->color : (*colors)[point]; }
  vec3 pssBackground() const { return render->background; }
  bool pssExact() const { return render->exact; }
  bool pssShadows() const { return render->shadows; }
  bool pssVolume() const { return render->volume != nullptr && !render->transfer.empty(); }
  vec4 pssVolumeSettings() const {
    const PssVolume& v = *render->volume;
    return vec4(v.smoothing(), v.reach(), v.step(), 0.0f);
  }
  vec3 pssVolumeLo() const { return render->volume->lo(); }
  float pssVolumeSide() const { return render->volume->side(); }
  ivec3 pssVolumeDims() const { return render->volume->dims(); }
  uint pssVolumeStart(uint c) const { return render->volume->start()[c]; }
  uint pssVolumeAt(uint k) const { return render->volume->order()[k]; }
  vec4 pssVolumePoint(uint i) const { return render->volume->points()[i]; }
  uint pssTransferCount() const { return uint(render->transfer.size()); }
  vec4 pssTransfer(uint k) const {
    return vec4(render->transfer[k].value, render->transfer[k].extinction, 0.0f, 0.0f);
  }
  vec4 pssTransferColor(uint k) const { return vec4(render->transfer[k].color, 0.0f); }

#include "shaders/pss.h"
#include "shaders/pss_volume.h"
#include "shaders/pss_trace.h"

 private:
  const PssSurface::Grid& grid_;
  const std::vector<vec3>& positions_;
  const std::vector<vec3>& normals_;
  const std::vector<float>& h_;
  const std::vector<PssPatch>& patches_;
  vec4 settings_;
};

#undef ISO_INOUT

}  // namespace pss_shader

namespace {

constexpr uint32_t kMaxCells = 1u << 22;  // the grid's cells at most

}  // namespace

PssSurface::PssSurface(std::vector<glm::vec3> positions, std::vector<glm::vec3> normals,
                       std::vector<float> h, const PssOptions& options)
    : positions_(std::move(positions)),
      normals_(std::move(normals)),
      h_(std::move(h)),
      options_(options) {
  const size_t n = positions_.size();
  ISO_CHECK(normals_.size() == n && h_.size() == n);
  env_ = std::make_unique<pss_shader::Env>(grid_, positions_, normals_, h_, patches_, options_);
  if (n == 0) return;
  // The grid: cells about the median h wide (measured fastest for camera rays: twice as wide
  // tests more trust regions a cell, half as wide walks more cells), at most kMaxCells of them.
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  float largest = 0.0f;
  for (size_t i = 0; i < n; ++i) {
    lo = glm::min(lo, positions_[i]);
    hi = glm::max(hi, positions_[i]);
    largest = std::max(largest, h_[i]);
  }
  std::vector<float> sorted = h_;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const float margin = largest * std::max(options_.trust, 1.0f);
  lo -= margin;
  hi += margin;
  const glm::vec3 extent = glm::max(hi - lo, glm::vec3(1e-6f));
  float side = std::max(sorted[n / 2], 1e-6f);
  while (double(std::ceil(extent.x / side)) * std::ceil(extent.y / side) *
             std::ceil(extent.z / side) > kMaxCells)
    side *= 1.25f;
  grid_.lo = lo;
  grid_.side = side;
  grid_.dims = glm::max(glm::ivec3(glm::ceil(extent / side)), glm::ivec3(1));
  const size_t cells = size_t(grid_.dims.x) * grid_.dims.y * grid_.dims.z;
  // Points by cell (counting sort).
  grid_.pointStart.assign(cells + 1, 0);
  for (const glm::vec3& p : positions_) ++grid_.pointStart[env_->pssCellIndex(env_->pssCellOf(p)) + 1];
  for (size_t c = 0; c < cells; ++c) grid_.pointStart[c + 1] += grid_.pointStart[c];
  grid_.points.resize(n);
  {
    std::vector<uint32_t> next(grid_.pointStart.begin(), grid_.pointStart.end() - 1);
    for (uint32_t i = 0; i < n; ++i)
      grid_.points[next[env_->pssCellIndex(env_->pssCellOf(positions_[i]))]++] = i;
  }
  // Each point's polynomial, fitted at the point; its trust region the point's own (b = trust ×
  // its h).
  patches_.resize(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    PssPatch p;
    if (!fitAt(positions_[i], p)) {
      // Alone: a disc of the point's own plane.
      const glm::vec3 axis =
          std::abs(normals_[i].x) < 0.6f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0);
      p.origin = glm::vec4(positions_[i], 0.0f);
      p.normal = glm::vec4(normals_[i], 0.0f);
      p.tangent = glm::vec4(glm::normalize(glm::cross(normals_[i], axis)), 0.0f);
      p.coefficients = glm::vec4(0.0f);
    }
    p.origin.w = options_.trust * h_[i];
    patches_[i] = p;
  });
  // Trust regions by cell: each ball listed in the cells it reaches into.
  std::vector<std::vector<uint32_t>> lists(cells);
  for (uint32_t i = 0; i < n; ++i) {
    const glm::vec3 c(patches_[i].origin);
    const float b = patches_[i].origin.w;
    const glm::ivec3 a = env_->pssCellOf(c - b), z = env_->pssCellOf(c + b);
    for (int x = a.x; x <= z.x; ++x)
      for (int y = a.y; y <= z.y; ++y)
        for (int k = a.z; k <= z.z; ++k) {
          const glm::vec3 clo = grid_.lo + glm::vec3(x, y, k) * side;
          const glm::vec3 nearest = glm::clamp(c, clo, clo + side);
          if (glm::dot(nearest - c, nearest - c) <= b * b)
            lists[env_->pssCellIndex({x, y, k})].push_back(i);
        }
  }
  grid_.reachStart.assign(cells + 1, 0);
  for (size_t c = 0; c < cells; ++c)
    grid_.reachStart[c + 1] = grid_.reachStart[c] + uint32_t(lists[c].size());
  grid_.reach.reserve(grid_.reachStart[cells]);
  for (const auto& list : lists) grid_.reach.insert(grid_.reach.end(), list.begin(), list.end());
}

PssSurface::~PssSurface() = default;

bool PssSurface::fitAt(const glm::vec3& x, PssPatch& patch) const {
  return env_->pssFit(x, patch.origin, patch.normal, patch.tangent, patch.coefficients);
}

bool PssSurface::project(const glm::vec3& x, glm::vec3& onSurface) const {
  PssPatch p;
  if (!fitAt(x, p)) return false;
  onSurface = glm::vec3(p.origin) + p.normal.w * glm::vec3(p.normal);
  return true;
}

bool PssSurface::intersectAll(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax,
                              PssHit& hit) const {
  bool found = false;
  for (uint32_t i = 0; i < patches_.size(); ++i) {
    float t = 0.0f;
    glm::vec3 normal(0.0f);
    const PssPatch& p = patches_[i];
    if (env_->pssIntersect(p.origin, p.normal, p.tangent, p.coefficients, o, d, tMin, tMax, t,
                           normal)) {
      tMax = t;
      hit = {t, normal, i, 0};
      found = true;
    }
  }
  return found;
}

bool PssSurface::intersect(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax,
                           PssMode mode, PssHit& hit) const {
  if (patches_.empty()) return false;
  return env_->pssHit(o, d, tMin, tMax, mode == PssMode::Exact, hit.t, hit.normal, hit.point,
                      hit.projections);
}

PssVolume::PssVolume(const std::vector<glm::vec3>& positions, const std::vector<float>& values,
                     float smoothing, float step) {
  ISO_CHECK(positions.size() == values.size());
  const size_t n = positions.size();
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (const glm::vec3& p : positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  if (n == 0) lo = hi = glm::vec3(0.0f);
  const glm::vec3 extent = glm::max(hi - lo, glm::vec3(1e-6f));
  smoothing_ = smoothing > 0.0f
                   ? smoothing
                   : std::cbrt(extent.x * extent.y * extent.z / float(std::max<size_t>(n, 1)));
  step_ = step > 0.0f ? step : smoothing_;
  // Cells as wide as the reach (a sample's points lie in the 3 × 3 × 3 around it), at most
  // kMaxCells of them.
  float side = reach();
  while (double(std::ceil(extent.x / side)) * std::ceil(extent.y / side) *
             std::ceil(extent.z / side) > kMaxCells)
    side *= 1.25f;
  smoothing_ = side / 3.0f;  // the reach is the side
  lo_ = lo;
  dims_ = glm::max(glm::ivec3(glm::ceil(extent / side)), glm::ivec3(1));
  const auto cellOf = [&](const glm::vec3& p) {
    const glm::ivec3 c = glm::clamp(glm::ivec3(glm::floor((p - lo_) / side)), glm::ivec3(0),
                                    dims_ - 1);
    return (size_t(c.z) * dims_.y + size_t(c.y)) * dims_.x + size_t(c.x);
  };
  const size_t cells = size_t(dims_.x) * dims_.y * dims_.z;
  start_.assign(cells + 1, 0);
  for (const glm::vec3& p : positions) ++start_[cellOf(p) + 1];
  for (size_t c = 0; c < cells; ++c) start_[c + 1] += start_[c];
  order_.resize(n);
  std::vector<uint32_t> next(start_.begin(), start_.end() - 1);
  for (uint32_t i = 0; i < n; ++i) order_[next[cellOf(positions[i])]++] = i;
  points_.resize(n);
  for (size_t i = 0; i < n; ++i) points_[i] = glm::vec4(positions[i], values[i]);
}

glm::vec3 pssRay(const PssSurface& surface, const std::vector<glm::vec3>& colors,
                 const PssRender& render, const glm::vec3& o, const glm::vec3& d) {
  pss_shader::Env env(surface.grid(), surface.positions(), surface.normals(), surface.h(),
                      surface.patches(), surface.options());
  env.render = &render;
  env.colors = &colors;
  return env.pssRayColor(o, d, pssScale(surface));
}

PssRays pssRays(const PssRender& render) {
  PssRays rays;
  rays.forward = glm::normalize(render.target - render.eye);
  glm::vec3 right = glm::cross(rays.forward, render.up);
  if (glm::dot(right, right) < 1e-12f) right = glm::cross(rays.forward, glm::vec3(1, 0, 0));
  right = glm::normalize(right);
  const float t = std::tan(glm::radians(render.fovDegrees) * 0.5f);
  rays.right = right * (t * float(render.width) / float(render.height));
  rays.up = glm::cross(right, rays.forward) * t;
  return rays;
}

float pssScale(const PssSurface& surface) {
  const PssSurface::Grid& grid = surface.grid();
  return glm::length(glm::vec3(grid.dims) * grid.side);
}

bool pssRefract(const PssSurface& surface, const glm::vec3& o, const glm::vec3& d, float ior,
                bool exact, glm::vec3& point, glm::vec3& normal, glm::vec3& bent) {
  PssRender render;
  render.exact = exact;
  const std::vector<glm::vec3> colors;
  pss_shader::Env env(surface.grid(), surface.positions(), surface.normals(), surface.h(),
                      surface.patches(), surface.options());
  env.render = &render;
  env.colors = &colors;
  uint32_t index = 0;
  return env.pssRefraction(o, d, ior, 0.0f, point, normal, bent, index);
}

std::vector<glm::vec3> renderPss(const PssSurface& surface, const std::vector<glm::vec3>& colors,
                                 const PssRender& render) {
  ISO_CHECK(colors.empty() || colors.size() == surface.size());
  pss_shader::Env env(surface.grid(), surface.positions(), surface.normals(), surface.h(),
                      surface.patches(), surface.options());
  env.render = &render;
  env.colors = &colors;
  const PssRays rays = pssRays(render);
  const float scale = pssScale(surface);
  std::vector<glm::vec3> pixels(size_t(render.width) * render.height);
  tbb::parallel_for(0, render.height, [&](int y) {
    for (int x = 0; x < render.width; ++x) {
      // Through the pixel's centre, as pss.comp.glsl.
      const float sx = (float(x) + 0.5f) / float(render.width) * 2.0f - 1.0f;
      const float sy = 1.0f - (float(y) + 0.5f) / float(render.height) * 2.0f;
      const glm::vec3 d = glm::normalize(rays.forward + sx * rays.right + sy * rays.up);
      pixels[size_t(y) * render.width + x] = env.pssRayColor(render.eye, d, scale);
    }
  });
  return pixels;
}

void fillPssParams(gpu::PssParams& q, const PssSurface* surface, bool colors,
                   const PssVolume* volume, const std::vector<PssTransferPoint>& transfer) {
  if (transfer.size() > gpu::kPssMaxTransfer)
    throw UsageError("a transfer function: at most " + std::to_string(gpu::kPssMaxTransfer) +
                     " points");
  if (surface) {
    const PssSurface::Grid& grid = surface->grid();
    q.gridLo = glm::vec4(grid.lo, grid.side);
    q.gridDims = glm::uvec4(glm::uvec3(grid.dims), q.gridDims.w);
    const PssOptions& o = surface->options();
    q.settings = glm::vec4(o.trust, o.reach, o.tolerance, float(o.maxProjections));
  }
  if (colors) q.image.z |= gpu::kPssColors;
  if (volume && !transfer.empty()) {
    q.volumeLo = glm::vec4(volume->lo(), volume->side());
    q.volumeDims = glm::uvec4(glm::uvec3(volume->dims()), uint32_t(transfer.size()));
    q.volumeSettings = glm::vec4(volume->smoothing(), volume->reach(), volume->step(), 0.0f);
    for (size_t k = 0; k < transfer.size(); ++k) {
      q.transfer[2 * k] = glm::vec4(transfer[k].value, transfer[k].extinction, 0.0f, 0.0f);
      q.transfer[2 * k + 1] = glm::vec4(transfer[k].color, 0.0f);
    }
  }
}

gpu::PssParams PssObject::params(const gpu::FrameParams& frame) const {
  gpu::PssParams q{};
  q.color = glm::vec4(frame.albedo.x, frame.albedo.y, frame.albedo.z, 0.0f);
  fillPssParams(q, surface.get(), !colors.empty(), volume.get(), transfer);
  if (exact) q.image.z |= gpu::kPssExact;
  q.eye.w = 1e-4f * pssScale(*surface);
  return q;
}

}  // namespace iso::viewer
