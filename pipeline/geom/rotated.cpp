// A shape turned about a pivot (makeRotated, shape.h): every query is turned into the shape's own
// frame and its answer back.
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

#include "pipeline/geom/shape.h"

namespace iso {
namespace {

glm::dmat3 rotationAbout(int axis, double degrees) {
  const double a = degrees * M_PI / 180.0, c = std::cos(a), s = std::sin(a);
  glm::dmat3 r(1.0);  // columns
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  r[u][u] = c;
  r[u][v] = s;
  r[v][u] = -s;
  r[v][v] = c;
  return r;
}

class Rotated final : public Shape {
 public:
  Rotated(std::unique_ptr<Shape> shape, const glm::dmat3& rotation, const glm::dvec3& pivot)
      : shape_(std::move(shape)), r_(rotation), inverse_(glm::transpose(rotation)),
        pivot_(pivot) {
    const glm::dvec3 lo = shape_->boundsMin(), hi = shape_->boundsMax();
    lo_ = glm::dvec3(HUGE_VAL);
    hi_ = glm::dvec3(-HUGE_VAL);
    for (int c = 0; c < 8; ++c) {
      const glm::dvec3 corner(c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y, c & 4 ? hi.z : lo.z);
      lo_ = glm::min(lo_, toWorld(corner));
      hi_ = glm::max(hi_, toWorld(corner));
    }
  }

  std::string name() const override { return shape_->name(); }
  double area() const override { return shape_->area(); }
  bool isClosed() const override { return shape_->isClosed(); }
  glm::dvec3 boundsMin() const override { return lo_; }
  glm::dvec3 boundsMax() const override { return hi_; }

  SurfacePoint sample(std::mt19937_64& rng) const override {
    const SurfacePoint p = shape_->sample(rng);
    return {toWorld(p.position), r_ * p.normal};
  }
  ClosestPoint closest(const glm::dvec3& query) const override {
    const ClosestPoint c = shape_->closest(toShape(query));
    return {toWorld(c.position), r_ * c.normal, c.distance};
  }
  std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                  double tMin, double tMax) const override {
    return shape_->intersect(toShape(origin), inverse_ * direction, tMin, tMax);
  }

 private:
  glm::dvec3 toWorld(const glm::dvec3& p) const { return pivot_ + r_ * (p - pivot_); }
  glm::dvec3 toShape(const glm::dvec3& p) const { return pivot_ + inverse_ * (p - pivot_); }

  std::unique_ptr<Shape> shape_;
  glm::dmat3 r_, inverse_;
  glm::dvec3 pivot_, lo_, hi_;
};

}  // namespace

std::unique_ptr<Shape> makeRotated(std::unique_ptr<Shape> shape, const glm::dvec3& degrees,
                                   const glm::dvec3& pivot) {
  const glm::dmat3 r =
      rotationAbout(2, degrees.z) * rotationAbout(1, degrees.y) * rotationAbout(0, degrees.x);
  return std::make_unique<Rotated>(std::move(shape), r, pivot);
}

}  // namespace iso
