// Point set surfaces on the CPU (pss.h): shaders/pss.h's intersection, the fits, the grid.
#include "viewer/pss.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <limits>

#include "iso/check.h"

namespace iso::viewer {
namespace pss_shader {
namespace {
using namespace glm;
#define ISO_INOUT(T) T&
#include "shaders/pss.h"
#undef ISO_INOUT
}  // namespace
}  // namespace pss_shader

namespace {

constexpr uint32_t kMaxCells = 1u << 22;  // the grid's cells at most

bool intersectPatch(const PssPatch& p, const glm::vec3& o, const glm::vec3& d, float tMin,
                    float tMax, float& t, glm::vec3& normal) {
  return pss_shader::pssIntersect(p.origin, p.normal, p.tangent, p.coefficients, o, d, tMin,
                                  tMax, t, normal);
}

// Solves the 4×4 system m x = r (Gaussian elimination, partial pivoting); false when singular.
bool solve4(double m[4][5], double x[4]) {
  for (int c = 0; c < 4; ++c) {
    int pivot = c;
    for (int r = c + 1; r < 4; ++r)
      if (std::abs(m[r][c]) > std::abs(m[pivot][c])) pivot = r;
    if (std::abs(m[pivot][c]) < 1e-300) return false;
    if (pivot != c)
      for (int k = 0; k < 5; ++k) std::swap(m[c][k], m[pivot][k]);
    for (int r = c + 1; r < 4; ++r) {
      const double f = m[r][c] / m[c][c];
      for (int k = c; k < 5; ++k) m[r][k] -= f * m[c][k];
    }
  }
  for (int c = 3; c >= 0; --c) {
    double s = m[c][4];
    for (int k = c + 1; k < 4; ++k) s -= m[c][k] * x[k];
    x[c] = s / m[c][c];
  }
  return true;
}

}  // namespace

PssSurface::PssSurface(std::vector<glm::vec3> positions, std::vector<glm::vec3> normals,
                       std::vector<float> h, const PssOptions& options)
    : positions_(std::move(positions)),
      normals_(std::move(normals)),
      h_(std::move(h)),
      options_(options) {
  const size_t n = positions_.size();
  ISO_CHECK(normals_.size() == n && h_.size() == n);
  if (n == 0) return;
  // The grid: cells about twice the median h wide, at most kMaxCells of them.
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  float largest = 0.0f;
  for (size_t i = 0; i < n; ++i) {
    lo = glm::min(lo, positions_[i]);
    hi = glm::max(hi, positions_[i]);
    largest = std::max(largest, h_[i]);
  }
  std::vector<float> sorted = h_;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const float margin = largest * std::max(options_.trust, options_.reach);
  lo -= margin;
  hi += margin;
  const glm::vec3 extent = glm::max(hi - lo, glm::vec3(1e-6f));
  float side = std::max(2.0f * sorted[n / 2], 1e-6f);
  while (double(std::ceil(extent.x / side)) * std::ceil(extent.y / side) *
             std::ceil(extent.z / side) > kMaxCells)
    side *= 1.25f;
  grid_.lo = lo;
  grid_.side = side;
  grid_.dims = glm::max(glm::ivec3(glm::ceil(extent / side)), glm::ivec3(1));
  const size_t cells = size_t(grid_.dims.x) * grid_.dims.y * grid_.dims.z;
  // Points by cell (counting sort).
  grid_.pointStart.assign(cells + 1, 0);
  for (const glm::vec3& p : positions_) ++grid_.pointStart[cellIndex(cellOf(p)) + 1];
  for (size_t c = 0; c < cells; ++c) grid_.pointStart[c + 1] += grid_.pointStart[c];
  grid_.points.resize(n);
  {
    std::vector<uint32_t> next(grid_.pointStart.begin(), grid_.pointStart.end() - 1);
    for (uint32_t i = 0; i < n; ++i) grid_.points[next[cellIndex(cellOf(positions_[i]))]++] = i;
  }
  // Each point's polynomial, fitted at the point.
  patches_.resize(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    PssPatch p;
    if (!fitAt(positions_[i], p)) {
      // Alone: a disc of the point's own plane.
      p.origin = glm::vec4(positions_[i], options_.trust * h_[i]);
      p.normal = glm::vec4(normals_[i], 0.0f);
      const glm::vec3 axis = std::abs(normals_[i].x) < 0.6f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0);
      p.tangent = glm::vec4(glm::normalize(glm::cross(normals_[i], axis)), 0.0f);
    }
    // The trust region is the point's (its h, not the nearest point's: that is itself).
    p.origin.w = options_.trust * h_[i];
    patches_[i] = p;
  });
  // Trust regions by cell: each ball listed in the cells its bounding box reaches into.
  std::vector<std::vector<uint32_t>> lists(cells);
  for (uint32_t i = 0; i < n; ++i) {
    const glm::vec3 c(patches_[i].origin);
    const float b = patches_[i].origin.w;
    const glm::ivec3 a = cellOf(c - b), z = cellOf(c + b);
    for (int x = a.x; x <= z.x; ++x)
      for (int y = a.y; y <= z.y; ++y)
        for (int k = a.z; k <= z.z; ++k) {
          // The ball against the cell's box.
          const glm::vec3 clo = grid_.lo + glm::vec3(x, y, k) * side;
          const glm::vec3 nearest = glm::clamp(c, clo, clo + side);
          if (glm::dot(nearest - c, nearest - c) <= b * b)
            lists[cellIndex({x, y, k})].push_back(i);
        }
  }
  grid_.reachStart.assign(cells + 1, 0);
  for (size_t c = 0; c < cells; ++c)
    grid_.reachStart[c + 1] = grid_.reachStart[c] + uint32_t(lists[c].size());
  grid_.reach.reserve(grid_.reachStart[cells]);
  for (const auto& list : lists) grid_.reach.insert(grid_.reach.end(), list.begin(), list.end());
}

glm::ivec3 PssSurface::cellOf(const glm::vec3& p) const {
  return glm::clamp(glm::ivec3(glm::floor((p - grid_.lo) / grid_.side)), glm::ivec3(0),
                    grid_.dims - 1);
}

size_t PssSurface::cellIndex(const glm::ivec3& c) const {
  return (size_t(c.z) * grid_.dims.y + size_t(c.y)) * grid_.dims.x + size_t(c.x);
}

void PssSurface::neighbours(const glm::vec3& x, float radius, std::vector<uint32_t>& out) const {
  out.clear();
  const glm::ivec3 a = cellOf(x - radius), z = cellOf(x + radius);
  for (int cz = a.z; cz <= z.z; ++cz)
    for (int cy = a.y; cy <= z.y; ++cy)
      for (int cx = a.x; cx <= z.x; ++cx) {
        const size_t c = cellIndex({cx, cy, cz});
        for (uint32_t k = grid_.pointStart[c]; k < grid_.pointStart[c + 1]; ++k) {
          const uint32_t i = grid_.points[k];
          const glm::vec3 v = positions_[i] - x;
          if (glm::dot(v, v) <= radius * radius) out.push_back(i);
        }
      }
}

bool PssSurface::fitAt(const glm::vec3& x, PssPatch& patch) const {
  thread_local std::vector<uint32_t> near;
  // The width of the weights: the nearest point's h, found in the cells around x.
  float hx = 0.0f, nearest = std::numeric_limits<float>::max();
  for (float radius = grid_.side; hx == 0.0f && radius <= 4.0f * grid_.side; radius *= 2.0f) {
    neighbours(x, radius, near);
    for (uint32_t i : near) {
      const float d = glm::dot(positions_[i] - x, positions_[i] - x);
      if (d < nearest) {
        nearest = d;
        hx = h_[i];
      }
    }
  }
  if (hx <= 0.0f) return false;
  neighbours(x, options_.reach * hx, near);
  if (near.size() < 3) return false;
  // The weighted normal and centroid: the plane H.
  const float inv = 1.0f / (hx * hx);
  glm::dvec3 normal(0.0), centroid(0.0);
  double weights = 0.0;
  thread_local std::vector<double> w;
  w.resize(near.size());
  for (size_t k = 0; k < near.size(); ++k) {
    const glm::vec3 v = positions_[near[k]] - x;
    w[k] = std::exp(-double(glm::dot(v, v)) * inv);
    normal += w[k] * glm::dvec3(normals_[near[k]]);
    centroid += w[k] * glm::dvec3(positions_[near[k]]);
    weights += w[k];
  }
  if (glm::length(normal) < 1e-12 * weights) return false;
  const glm::vec3 n = glm::vec3(glm::normalize(normal));
  const glm::vec3 c = glm::vec3(centroid / weights);
  const glm::vec3 q = x - glm::dot(x - c, n) * n;
  const glm::vec3 axis = std::abs(n.x) < 0.6f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0);
  const glm::vec3 u = glm::normalize(glm::cross(n, axis)), v = glm::cross(n, u);
  // g(X, Y) = A X² + B Y² + C X Y + D by weighted least squares of the heights F over H.
  double m[4][5] = {};
  for (size_t k = 0; k < near.size(); ++k) {
    const glm::vec3 r = positions_[near[k]] - q;
    const double X = glm::dot(r, u), Y = glm::dot(r, v), F = glm::dot(r, n);
    const double phi[4] = {X * X, Y * Y, X * Y, 1.0};
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) m[a][b] += w[k] * phi[a] * phi[b];
      m[a][4] += w[k] * phi[a] * F;
    }
  }
  double coefficients[4] = {0, 0, 0, 0};
  // Too few points around to bend the plane (or all on a line): the plane through them.
  const double scale = m[3][3] * double(hx) * hx * hx * hx;
  for (int a = 0; a < 3; ++a) m[a][a] += 1e-6 * scale;  // a little ridge keeps it solvable
  if (!solve4(m, coefficients)) {
    coefficients[0] = coefficients[1] = coefficients[2] = 0.0;
    coefficients[3] = m[3][4] / m[3][3];
  }
  patch.origin = glm::vec4(q, options_.trust * hx);
  patch.normal = glm::vec4(n, float(coefficients[3]));
  patch.tangent = glm::vec4(u, float(coefficients[0]));
  patch.coefficients = glm::vec4(float(coefficients[1]), float(coefficients[2]), 0.0f, 0.0f);
  return true;
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
    if (intersectPatch(patches_[i], o, d, tMin, tMax, t, normal)) {
      tMax = t;
      hit = {t, normal, i, 0};
      found = true;
    }
  }
  return found;
}

bool PssSurface::fast(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax,
                      PssHit& hit) const {
  if (patches_.empty()) return false;
  // The ray's span inside the grid's box.
  const glm::vec3 hiBox = grid_.lo + glm::vec3(grid_.dims) * grid_.side;
  float t0 = tMin, t1 = tMax;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-30f) {
      if (o[a] < grid_.lo[a] || o[a] > hiBox[a]) return false;
      continue;
    }
    float near = (grid_.lo[a] - o[a]) / d[a], far = (hiBox[a] - o[a]) / d[a];
    if (near > far) std::swap(near, far);
    t0 = std::max(t0, near);
    t1 = std::min(t1, far);
  }
  if (!(t0 <= t1)) return false;
  // Amanatides and Woo's walk through the cells from t0.
  glm::ivec3 cell = cellOf(o + t0 * d);
  glm::ivec3 step(0);
  glm::vec3 next(std::numeric_limits<float>::max()), delta(std::numeric_limits<float>::max());
  for (int a = 0; a < 3; ++a) {
    if (d[a] > 0.0f) {
      step[a] = 1;
      next[a] = (grid_.lo[a] + float(cell[a] + 1) * grid_.side - o[a]) / d[a];
      delta[a] = grid_.side / d[a];
    } else if (d[a] < 0.0f) {
      step[a] = -1;
      next[a] = (grid_.lo[a] + float(cell[a]) * grid_.side - o[a]) / d[a];
      delta[a] = -grid_.side / d[a];
    }
  }
  bool found = false;
  float best = tMax;
  while (true) {
    const size_t c = cellIndex(cell);
    for (uint32_t k = grid_.reachStart[c]; k < grid_.reachStart[c + 1]; ++k) {
      const uint32_t i = grid_.reach[k];
      float t = 0.0f;
      glm::vec3 normal(0.0f);
      if (intersectPatch(patches_[i], o, d, tMin, best, t, normal)) {
        best = t;
        hit = {t, normal, i, 0};
        found = true;
      }
    }
    const int a = next.x < next.y ? (next.x < next.z ? 0 : 2) : (next.y < next.z ? 1 : 2);
    // Every patch reaching past this cell's exit was tested: a hit before it is the first.
    if (found && best <= next[a]) return true;
    if (next[a] > t1) return found;
    cell[a] += step[a];
    if (cell[a] < 0 || cell[a] >= grid_.dims[a]) return found;
    next[a] += delta[a];
  }
}

bool PssSurface::intersect(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax,
                           PssMode mode, PssHit& hit) const {
  if (!fast(o, d, tMin, tMax, hit)) return false;
  if (mode == PssMode::Fast) return true;
  // Exact: project the hit onto the MLS surface; while it moves, intersect the ray with the
  // polynomial fitted there (or, outside its trust region, go on to the next stored one).
  float t = hit.t;
  for (int k = 0; k < options_.maxProjections; ++k) {
    const glm::vec3 x = o + t * d;
    PssPatch p;
    if (!fitAt(x, p)) break;
    ++hit.projections;
    const glm::vec3 n(p.normal), onSurface = glm::vec3(p.origin) + p.normal.w * n;
    const float h = p.origin.w / options_.trust;
    if (glm::length(onSurface - x) < options_.tolerance * h) {
      hit.t = t;
      hit.normal = n;  // the fitted polynomial's normal over its origin
      return true;
    }
    float next = 0.0f;
    glm::vec3 normal(0.0f);
    if (intersectPatch(p, o, d, tMin, tMax, next, normal)) {
      t = next;
      hit.normal = normal;
      continue;
    }
    PssHit further;
    if (!fast(o, d, t + 1e-4f * h, tMax, further)) break;
    t = further.t;
    hit.point = further.point;
    hit.normal = further.normal;
  }
  hit.t = t;
  return true;
}

}  // namespace iso::viewer
