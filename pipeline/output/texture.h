// Appearance baked into corner colors: triplanar texture projection (specs/pipeline.md §16).
#pragma once

#include <filesystem>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "iso/format.h"
#include "iso/surface.h"
#include "pipeline/base/options.h"
#include "base/image.h"

namespace iso {

struct PointSet;

// An image projected along the three axes and blended by the surface normal: along axis a the
// image's (u, v) are the other two world coordinates (x: (y, z), y: (x, z), z: (x, y)) divided by
// the scale, repeating, v up; the three samples are weighted by |n_a|^P, normalized.
class TriplanarTexture {
 public:
  TriplanarTexture(LinearImage image, double scale, double sharpness);
  // The color at a world position with the surface normal there (either sign).
  glm::vec3 color(const glm::dvec3& world, const glm::dvec3& normal) const;
  // The image at (u, v) in repeats, bilinear between texel centres.
  glm::vec3 sample(double u, double v) const;
  double scale() const { return scale_; }

 private:
  LinearImage image_;
  double scale_, sharpness_;
};

// The texture's colors at the points, multiplied into the points' own colors when they have some
// (a detail texture over a scan's colors). Points in frame units, normals set.
void texturePoints(PointSet& points, const Frame& frame, const TriplanarTexture& texture);

struct CornerField;
struct LodField;
// The same at the corners of the filled leaves (those in use) and of the levels of detail: at each
// corner's projection p − f·n onto the zero set of its value f, normal n (frame units), multiplied
// into its color when `modulate`, else replacing it.
void textureCorners(CornerField& leaves, LodField& lod, const Frame& frame,
                    const TriplanarTexture& texture, bool modulate);

}  // namespace iso
