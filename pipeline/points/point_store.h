// The points of raw scans held in memory for viewing (`iso view SCAN`), compactly, and the
// subsample of them to draw from a view: every point the view can show at a pixel's detail,
// within a budget, and a sparse rest around it.
#pragma once

#include <cstdint>
#include <glm/gtc/type_precision.hpp>
#include <glm/vec3.hpp>
#include <vector>

#include "pipeline/io/point_cloud.h"

namespace iso {

// What a camera sees, for choosing points: its eye, its unit axes and its pixels.
struct PointView {
  glm::dvec3 eye{0.0}, forward{0, 0, -1}, right{1, 0, 0}, up{0, 1, 0};  // world
  double tanHalfHeight = 0.364;  // tan of half the vertical field of view
  double aspect = 1.0;           // width over height
  uint32_t height = 1024;        // pixels

  // The world size of a pixel at `distance` along the view.
  double footprint(double distance) const { return distance * 2.0 * tanHalfHeight / height; }
  // Whether the box [lo, hi] reaches into the view, widened by `margin` (a fraction of the
  // field of view on each side) so that a small turn still finds points.
  bool sees(const glm::dvec3& lo, const glm::dvec3& hi, double margin = 0.15) const;
  // The distance from the eye to the nearest point of the box (0 inside).
  static double distance(const glm::dvec3& eye, const glm::dvec3& lo, const glm::dvec3& hi);
};

// Points added batch by batch, one object (file) after another, kept as 12-byte positions
// (relative to the first point), 16-bit linear colors and float normals where the object has
// them; then indexed in a grid of cubic cells, so that a view can take, from each cell, every
// k-th of its points.
class PointStore {
 public:
  // Appends `batch` to object `object` (objects in order: 0, then 1, ...). index() again after.
  void add(size_t object, const PointCloud& batch);
  uint64_t size() const { return total_; }
  size_t objects() const { return objects_.size(); }
  // The points' box (world), once some were added.
  glm::dvec3 lo() const { return lo_; }
  glm::dvec3 hi() const { return hi_; }

  // Every `stride`-th point, counting across the objects: one cloud an object.
  std::vector<PointCloud> every(uint64_t stride) const;

  // Bins the points into cells (after the last add; again after more were added).
  void index();
  // At most maxPoints points (one cloud an object) for `view`: each cell the view sees keeps
  // enough of its points to put one on every pixel its faces cover from their nearest distance
  // (2 (side / footprint)² of them, every k-th in reading order) or all it has; every cell keeps
  // at least the share of a uniform subsample of a tenth of maxPoints. When that exceeds
  // maxPoints, the cells seen keep a smaller share, the same fraction of what they asked for.
  // How many points a view keeps, and how many of those lie in cells it sees.
  struct Choice {
    uint64_t kept = 0, seen = 0;
  };
  std::vector<PointCloud> forView(const PointView& view, uint64_t maxPoints,
                                  Choice* choice = nullptr) const;
  // What forView keeps of each cell (`keep`, in the cells' order, when not null).
  Choice choose(const PointView& view, uint64_t maxPoints, std::vector<uint32_t>* keep) const;
  // Drops every 2nd point (counting across the objects) when the points outgrow memory.
  void thin();

 private:
  struct Object {
    uint64_t first = 0;  // index of its first point across the objects
    std::vector<glm::vec3> positions;  // minus origin_
    std::vector<glm::u16vec3> colors;  // linear, × 65535
    std::vector<glm::vec3> normals;
  };
  struct Cell {
    uint64_t key = 0;       // x | y << 21 | z << 42
    uint64_t begin = 0;     // into order_
    uint32_t count = 0;
  };
  void append(PointCloud& out, size_t object, uint64_t index) const;
  glm::dvec3 cellLo(const Cell& c) const;

  std::vector<Object> objects_;
  uint64_t total_ = 0;
  glm::dvec3 origin_{0.0}, lo_{0.0}, hi_{0.0};
  // The grid: cells of side cellSide_ from lo_, the occupied ones sorted by key, and the points'
  // indices cell after cell, in reading order within a cell.
  double cellSide_ = 1.0;
  std::vector<Cell> cells_;
  std::vector<uint32_t> order_;
};

}  // namespace iso
