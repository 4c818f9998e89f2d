// Triplanar texture projection (pipeline/output/texture.h).
#include "pipeline/output/texture.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <stdexcept>

#include "iso/error.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/points.h"

namespace iso {

TriplanarTexture::TriplanarTexture(LinearImage image, double scale, double sharpness)
    : image_(std::move(image)), scale_(scale), sharpness_(sharpness) {
  if (image_.width == 0 || image_.height == 0 || image_.texels.empty())
    throw UsageError("a texture needs a non-empty image");
  if (!(scale_ > 0.0) || !std::isfinite(scale_))
    throw UsageError("the texture scale must be positive");
}

glm::vec3 TriplanarTexture::sample(double u, double v) const {
  // Texel centres at (i + 0.5) / width; rows from the top, v up.
  const double x = (u - std::floor(u)) * image_.width - 0.5;
  const double y = (1.0 - (v - std::floor(v))) * image_.height - 0.5;
  const double fx = std::floor(x), fy = std::floor(y);
  const auto wrap = [](double i, uint32_t n) {
    const int64_t k = int64_t(i) % int64_t(n);
    return uint32_t(k < 0 ? k + n : k);
  };
  const uint32_t x0 = wrap(fx, image_.width), x1 = wrap(fx + 1.0, image_.width);
  const uint32_t y0 = wrap(fy, image_.height), y1 = wrap(fy + 1.0, image_.height);
  const float tx = float(x - fx), ty = float(y - fy);
  const glm::vec3 top = image_.at(x0, y0) * (1.0f - tx) + image_.at(x1, y0) * tx;
  const glm::vec3 bottom = image_.at(x0, y1) * (1.0f - tx) + image_.at(x1, y1) * tx;
  return top * (1.0f - ty) + bottom * ty;
}

glm::vec3 TriplanarTexture::color(const glm::dvec3& world, const glm::dvec3& normal) const {
  const double length = glm::length(normal);
  const glm::dvec3 n = length > 0.0 ? glm::abs(normal) / length : glm::dvec3(1.0 / std::sqrt(3.0));
  const glm::dvec3 w(std::pow(n.x, sharpness_), std::pow(n.y, sharpness_),
                     std::pow(n.z, sharpness_));
  const double sum = w.x + w.y + w.z;
  const glm::dvec3 p = world / scale_;
  glm::dvec3 c(0.0);
  if (w.x > 0.0) c += w.x * glm::dvec3(sample(p.y, p.z));
  if (w.y > 0.0) c += w.y * glm::dvec3(sample(p.x, p.z));
  if (w.z > 0.0) c += w.z * glm::dvec3(sample(p.x, p.y));
  return glm::vec3(c / sum);
}

void texturePoints(PointSet& points, const Frame& frame, const TriplanarTexture& texture) {
  const bool modulate = points.hasColors();
  if (!modulate) points.color.resize(points.size());
  tbb::parallel_for(size_t{0}, points.size(), [&](size_t i) {
    const glm::vec3 c =
        texture.color(toWorld(glm::dvec3(points.position[i]), frame), glm::dvec3(points.normal[i]));
    points.color[i] = modulate ? points.color[i] * c : c;
  });
}

void textureCorners(CornerField& leaves, LodField& lod, const Frame& frame,
                    const TriplanarTexture& texture, bool modulate) {
  const auto bake = [&](const GridPoint& point, CornerSample& s) {
    const glm::dvec3 n(s.normal);
    const glm::vec3 c =
        texture.color(toWorld(gridToFrame(point) - double(s.distance) * n, frame), n);
    s.color = modulate ? s.color * c : c;
  };
  tbb::parallel_for(uint32_t{0}, uint32_t(leaves.size()), [&](uint32_t e) {
    if (leaves.coarsestLevel[e] != kUnusedCorner) bake(leaves.point(e), leaves.value[e]);
  });
  tbb::parallel_for(uint32_t{0}, uint32_t(lod.value.size()),
                    [&](uint32_t e) { bake(lod.point(e), lod.value[e]); });
}

}  // namespace iso
