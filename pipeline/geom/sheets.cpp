// Open squares parallel to the xy plane: the plane (one square) and the sheets (two squares facing
// away from each other, the sides of a thin slab without its rim).
#include <algorithm>
#include <cmath>
#include <vector>

#include "pipeline/geom/analytic.h"
#include "pipeline/geom/random.h"

namespace iso {
namespace {

// One square |x|,|y| <= halfSize at height z (relative to the centre), facing +z or -z.
struct Layer {
  double z;
  double normalZ;
};

class Squares final : public Shape {
 public:
  Squares(std::string name, const glm::dvec3& center, double halfSize, std::vector<Layer> layers)
      : name_(std::move(name)), center_(center), half_(halfSize), layers_(std::move(layers)) {}

  std::string name() const override { return name_; }
  double area() const override { return 4.0 * half_ * half_ * double(layers_.size()); }
  bool isClosed() const override { return false; }
  glm::dvec3 boundsMin() const override { return center_ + glm::dvec3(-half_, -half_, lowest()); }
  glm::dvec3 boundsMax() const override { return center_ + glm::dvec3(half_, half_, highest()); }

  // Layers have equal areas: pick one uniformly, then a uniform point on it.
  SurfacePoint sample(std::mt19937_64& rng) const override {
    const size_t count = layers_.size();
    const Layer& layer = layers_[std::min(size_t(double(count) * uniform01(rng)), count - 1)];
    const double x = half_ * (2.0 * uniform01(rng) - 1.0);
    const double y = half_ * (2.0 * uniform01(rng) - 1.0);
    return {center_ + glm::dvec3(x, y, layer.z), glm::dvec3(0.0, 0.0, layer.normalZ)};
  }

  // The nearest layer's clamped point; the first (upper) layer wins ties.
  ClosestPoint closest(const glm::dvec3& query) const override {
    const glm::dvec3 d = query - center_;
    const double x = std::clamp(d.x, -half_, half_);
    const double y = std::clamp(d.y, -half_, half_);
    const double planar2 = (d.x - x) * (d.x - x) + (d.y - y) * (d.y - y);
    const Layer* best = nullptr;
    double best2 = 0.0;
    for (const Layer& layer : layers_) {
      const double d2 = planar2 + (d.z - layer.z) * (d.z - layer.z);
      if (best != nullptr && d2 >= best2) continue;
      best = &layer;
      best2 = d2;
    }
    return {center_ + glm::dvec3(x, y, best->z), glm::dvec3(0.0, 0.0, best->normalZ),
            std::sqrt(best2)};
  }

  // A ray lying in a layer's plane is not counted as meeting it.
  std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                  double tMin, double tMax) const override {
    if (direction.z == 0.0) return std::nullopt;
    const glm::dvec3 o = origin - center_;
    std::optional<double> nearest;
    for (const Layer& layer : layers_) {
      const double t = (layer.z - o.z) / direction.z;
      if (!(t > tMin && t < tMax) || (nearest && t >= *nearest)) continue;
      if (std::abs(o.x + t * direction.x) <= half_ && std::abs(o.y + t * direction.y) <= half_)
        nearest = t;
    }
    return nearest;
  }

 private:
  double lowest() const {
    return std::min_element(layers_.begin(), layers_.end(),
                            [](const Layer& a, const Layer& b) { return a.z < b.z; })
        ->z;
  }
  double highest() const {
    return std::max_element(layers_.begin(), layers_.end(),
                            [](const Layer& a, const Layer& b) { return a.z < b.z; })
        ->z;
  }

  std::string name_;
  glm::dvec3 center_;
  double half_;
  std::vector<Layer> layers_;
};

}  // namespace

std::unique_ptr<Shape> makePlane(const glm::dvec3& center, double halfSize) {
  return std::make_unique<Squares>("plane", center, halfSize, std::vector<Layer>{{0.0, 1.0}});
}

std::unique_ptr<Shape> makeSheets(const glm::dvec3& center, double halfSize, double gap) {
  return std::make_unique<Squares>("sheets", center, halfSize,
                                   std::vector<Layer>{{0.5 * gap, 1.0}, {-0.5 * gap, -1.0}});
}

}  // namespace iso
