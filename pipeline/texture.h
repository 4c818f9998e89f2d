// Appearance baked into corner colors: triplanar texture projection (specs/pipeline.md §16).
#pragma once

#include <filesystem>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "io/image.h"
#include "iso/format.h"
#include "iso/surface.h"

namespace iso {

struct PointSet;

// Where a texture is sampled: at every point (its colors then reach the corners as point colors
// do, averaged by the signed distance's weights), or at every corner's projection onto the zero
// set (the image's detail down to the leaf size, without the points' averaging).
enum class TextureAt { Points, Corners };

struct TextureOptions {
  std::filesystem::path image;  // empty: no texture
  double scale = 0.0;           // world units one repeat of the image spans; 0: the frame's size
  double sharpness = 4.0;       // P of the blend weights |n·axis|^P
  TextureAt at = TextureAt::Corners;
  bool enabled() const { return !image.empty(); }
};

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
