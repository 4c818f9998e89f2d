// Points held for viewing, and a view's subsample of them (point_store.h).
#include "pipeline/points/point_store.h"

#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>

namespace iso {
namespace {

constexpr uint32_t kMinCellsAcross = 32;   // the grid's longest side, in cells, at least
constexpr uint32_t kMaxCellsAcross = 256;  // and at most
constexpr double kPointsPerCell = 1000.0;  // about, on a surface (cells across ~ √(n / this))
constexpr double kBaseShare = 0.1;         // of the budget, spread over every cell
constexpr double kPointsPerPixel = 2.0;    // a seen cell's points: this × (side / footprint)²

// x rounded down or up, up with probability its fraction (a fixed fraction for each cell, so that
// the cells' sum comes out right on average and grows with x).
uint32_t dithered(double x, size_t cell) {
  const double offset = std::fmod(double(cell) * 0.6180339887498949, 1.0);
  return uint32_t(std::floor(x + offset));
}

}  // namespace

bool PointView::sees(const glm::dvec3& lo, const glm::dvec3& hi, double margin) const {
  const double tv = tanHalfHeight * (1.0 + margin), th = tv * aspect;
  const glm::dvec3 planes[] = {forward, forward * th - right, forward * th + right,
                               forward * tv - up, forward * tv + up};
  for (const glm::dvec3& n : planes) {
    // The box's corner farthest along n: outside when even it lies behind the plane.
    const glm::dvec3 corner(n.x >= 0 ? hi.x : lo.x, n.y >= 0 ? hi.y : lo.y,
                            n.z >= 0 ? hi.z : lo.z);
    if (glm::dot(n, corner - eye) < 0.0) return false;
  }
  return true;
}

double PointView::distance(const glm::dvec3& eye, const glm::dvec3& lo, const glm::dvec3& hi) {
  return glm::length(glm::clamp(eye, lo, hi) - eye);
}

void PointStore::add(size_t object, const PointCloud& batch) {
  while (objects_.size() <= object) objects_.push_back({total_, {}, {}, {}});
  if (batch.size() == 0) return;
  if (total_ == 0) origin_ = lo_ = hi_ = batch.positions[0];
  Object& o = objects_[object];
  for (size_t i = 0; i < batch.size(); ++i) {
    const glm::dvec3& p = batch.positions[i];
    lo_ = glm::min(lo_, p);
    hi_ = glm::max(hi_, p);
    o.positions.push_back(glm::vec3(p - origin_));
    if (batch.hasColors())
      o.colors.push_back(glm::u16vec3(glm::round(glm::clamp(batch.colors[i], 0.0f, 1.0f) *
                                                 65535.0f)));
    if (batch.hasNormals()) o.normals.push_back(batch.normals[i]);
  }
  total_ += batch.size();
}

void PointStore::append(PointCloud& out, size_t object, uint64_t index) const {
  const Object& o = objects_[object];
  const size_t i = size_t(index - o.first);
  out.positions.push_back(glm::dvec3(o.positions[i]) + origin_);
  if (!o.colors.empty()) out.colors.push_back(glm::vec3(o.colors[i]) / 65535.0f);
  if (!o.normals.empty()) out.normals.push_back(o.normals[i]);
}

std::vector<PointCloud> PointStore::every(uint64_t stride) const {
  std::vector<PointCloud> out(objects_.size());
  stride = std::max<uint64_t>(stride, 1);
  for (size_t f = 0; f < objects_.size(); ++f) {
    const Object& o = objects_[f];
    // The first index of this object that is a multiple of the stride.
    for (uint64_t i = (o.first + stride - 1) / stride * stride; i < o.first + o.positions.size();
         i += stride) {
      append(out[f], f, i);
    }
  }
  return out;
}

void PointStore::thin() {
  uint64_t first = 0;
  for (Object& o : objects_) {
    size_t to = 0;
    for (size_t i = 0; i < o.positions.size(); ++i) {
      if ((o.first + i) % 2 != 0) continue;
      o.positions[to] = o.positions[i];
      if (!o.colors.empty()) o.colors[to] = o.colors[i];
      if (!o.normals.empty()) o.normals[to] = o.normals[i];
      ++to;
    }
    o.positions.resize(to);
    if (!o.colors.empty()) o.colors.resize(to);
    if (!o.normals.empty()) o.normals.resize(to);
    o.first = first;
    first += to;
  }
  total_ = first;
  cells_.clear();
  order_.clear();
}

glm::dvec3 PointStore::cellLo(const Cell& c) const {
  const glm::dvec3 xyz(double(c.key & 0x1FFFFF), double((c.key >> 21) & 0x1FFFFF),
                       double(c.key >> 42));
  return lo_ + xyz * cellSide_;
}

void PointStore::index() {
  cells_.clear();
  order_.clear();
  if (total_ == 0) return;
  const glm::dvec3 extent = hi_ - lo_;
  const double longest = std::max({extent.x, extent.y, extent.z, 1e-9});
  const uint32_t across = std::clamp<uint32_t>(
      uint32_t(std::ceil(std::sqrt(double(total_) / kPointsPerCell))), kMinCellsAcross,
      kMaxCellsAcross);
  cellSide_ = longest / across * (1.0 + 1e-9);
  const glm::u64vec3 dims = glm::max(glm::u64vec3(glm::ceil(extent / cellSide_)), uint64_t(1));
  const auto cellOf = [&](const glm::vec3& p) {
    const glm::dvec3 at = (glm::dvec3(p) + origin_ - lo_) / cellSide_;
    const glm::u64vec3 c = glm::min(glm::u64vec3(glm::max(at, 0.0)), dims - uint64_t(1));
    return (c.z * dims.y + c.y) * dims.x + c.x;
  };
  // Counting sort by cell: counts, their prefix sums, then the indices in reading order.
  std::vector<uint32_t> counts(size_t(dims.x * dims.y * dims.z) + 1, 0);
  for (const Object& o : objects_)
    for (const glm::vec3& p : o.positions) ++counts[cellOf(p) + 1];
  for (size_t c = 1; c < counts.size(); ++c) counts[c] += counts[c - 1];
  for (size_t c = 0; c + 1 < counts.size(); ++c)
    if (counts[c + 1] > counts[c]) {
      const uint64_t x = c % dims.x, y = (c / dims.x) % dims.y, z = c / (dims.x * dims.y);
      cells_.push_back({x | y << 21 | z << 42, counts[c], counts[c + 1] - counts[c]});
    }
  order_.resize(total_);
  for (const Object& o : objects_)
    for (size_t i = 0; i < o.positions.size(); ++i)
      order_[counts[cellOf(o.positions[i])]++] = uint32_t(o.first + i);
}

PointStore::Choice PointStore::choose(const PointView& view, uint64_t maxPoints,
                                      std::vector<uint32_t>* keep) const {
  const size_t n = cells_.size();
  std::vector<uint32_t> base(n), want(n, 0);
  const double share = std::min(1.0, kBaseShare * double(maxPoints) / double(std::max<uint64_t>(total_, 1)));
  for (size_t c = 0; c < n; ++c) {
    const Cell& cell = cells_[c];
    base[c] = std::min(cell.count, dithered(cell.count * share, c));
    const glm::dvec3 lo = cellLo(cell), hi = lo + cellSide_;
    if (!view.sees(lo, hi)) continue;
    const double footprint =
        view.footprint(std::max(PointView::distance(view.eye, lo, hi), 1e-9 * cellSide_));
    const double pixels = kPointsPerPixel * (cellSide_ / footprint) * (cellSide_ / footprint);
    want[c] = uint32_t(std::min<double>(cell.count, std::ceil(pixels)));
  }
  const auto kept = [&](size_t c, double scale) {
    return std::max(base[c], std::min(want[c], dithered(scale * want[c], c)));
  };
  const auto total = [&](double scale) {
    uint64_t sum = 0;
    for (size_t c = 0; c < n; ++c) sum += kept(c, scale);
    return sum;
  };
  double scale = 1.0;
  if (total(1.0) > maxPoints) {
    double a = 0.0, b = 1.0;  // total(a) fits (or nothing does), total(b) does not
    for (int i = 0; i < 40; ++i) {
      const double m = 0.5 * (a + b);
      (total(m) <= maxPoints ? a : b) = m;
    }
    scale = a;
  }
  Choice choice;
  if (keep) keep->assign(n, 0);
  for (size_t c = 0; c < n; ++c) {
    const uint32_t k = kept(c, scale);
    choice.kept += k;
    if (want[c] > 0) choice.seen += k;
    if (keep) (*keep)[c] = k;
  }
  return choice;
}

std::vector<PointCloud> PointStore::forView(const PointView& view, uint64_t maxPoints,
                                            Choice* choice) const {
  std::vector<uint32_t> keep;
  const Choice c = choose(view, maxPoints, &keep);
  if (choice) *choice = c;
  // The indices kept, every k-th of each cell in reading order, then sorted: each object's
  // points in reading order.
  std::vector<uint32_t> chosen;
  for (size_t c = 0; c < cells_.size(); ++c) {
    const Cell& cell = cells_[c];
    for (uint32_t j = 0; j < keep[c]; ++j)
      chosen.push_back(order_[cell.begin + uint64_t(j) * cell.count / keep[c]]);
  }
  std::sort(chosen.begin(), chosen.end());
  std::vector<PointCloud> out(objects_.size());
  size_t f = 0;
  for (uint32_t i : chosen) {
    while (f + 1 < objects_.size() && objects_[f + 1].first <= i) ++f;
    append(out[f], f, i);
  }
  return out;
}

}  // namespace iso
