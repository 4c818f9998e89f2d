// Point set surfaces on the CPU (shaders/pss.h; specs/viewer.md, "Point set surfaces"): each
// point's local polynomial fitted by weighted least squares over its neighbours, a uniform grid
// that lists the points of each cell and the trust regions reaching into it, and a ray's first
// hit: fast (the nearest stored polynomial inside its trust region) or exact (the hit projected
// onto the moving-least-squares surface and the ray intersected again with the polynomial fitted
// there, until the projection moves less than a tolerance).
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <memory>
#include <vector>

#include "shaders/shared.h"

namespace iso::viewer {

namespace pss_shader {
class Env;
}

// A local polynomial and its trust region (shaders/pss.h): (origin, b), (n, D), (u, A), (B, C).
struct PssPatch {
  glm::vec4 origin{0.0f}, normal{0.0f}, tangent{0.0f}, coefficients{0.0f};
};

struct PssOptions {
  float trust = 0.75f;       // b = trust × h (Adamson and Alexa: 0.5 h < b < h)
  float reach = 2.5f;        // neighbours within reach × h weigh in a fit (Gaussian of width h)
  float tolerance = 1e-3f;   // exact mode: done when a projection moves less than this × h
  int maxProjections = 8;    // exact mode: projections of one hit at most
};

enum class PssMode { Fast, Exact };

struct PssHit {
  float t = 0.0f;
  glm::vec3 normal{0.0f};  // unit, on the side of the points' normals
  uint32_t point = 0;      // whose stored polynomial the search hit first
  int projections = 0;     // exact mode: MLS projections made
};

class PssSurface {
 public:
  // Points with unit normals (oriented; they choose each polynomial's side) and feature sizes h
  // (the width of the Gaussian weights: e.g. the conversion's radii).
  PssSurface(std::vector<glm::vec3> positions, std::vector<glm::vec3> normals,
             std::vector<float> h, const PssOptions& options = {});
  ~PssSurface();
  PssSurface(const PssSurface&) = delete;
  PssSurface& operator=(const PssSurface&) = delete;

  // Cells of `side` from `lo`: each point once (points, from pointStart[cell]) and each trust
  // region reaching in (reach, from reachStart[cell]); the GPU reads the same arrays.
  struct Grid {
    glm::vec3 lo{0.0f};
    float side = 1.0f;
    glm::ivec3 dims{1};
    std::vector<uint32_t> pointStart, points, reachStart, reach;
  };
  const Grid& grid() const { return grid_; }

  size_t size() const { return positions_.size(); }
  const std::vector<glm::vec3>& positions() const { return positions_; }
  const std::vector<glm::vec3>& normals() const { return normals_; }
  const std::vector<float>& h() const { return h_; }
  const std::vector<PssPatch>& patches() const { return patches_; }
  const PssOptions& options() const { return options_; }

  // The first hit of o + t d (d unit) for t in (tMin, tMax).
  bool intersect(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax, PssMode mode,
                 PssHit& hit) const;
  // The fast mode over every patch, without the grid (the grid's referee).
  bool intersectAll(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax,
                    PssHit& hit) const;

  // The polynomial fitted at x over the points around it (weights of the nearest point's h),
  // its frame's origin the projection of x onto the weighted plane; false where no point is near.
  bool fitAt(const glm::vec3& x, PssPatch& patch) const;
  // The moving-least-squares projection of x: the fitted polynomial's point over x's foot.
  bool project(const glm::vec3& x, glm::vec3& onSurface) const;

 private:
  std::vector<glm::vec3> positions_, normals_;
  std::vector<float> h_;
  PssOptions options_;
  std::vector<PssPatch> patches_;
  Grid grid_;
  std::unique_ptr<pss_shader::Env> env_;  // shaders/pss.h over the members above
};

// Scattered data inside the surface (its material boundary): points with a value each, in a grid
// of cells `reach` wide, read by Gaussian-weighted means (shaders/pss_trace.h).
class PssVolume {
 public:
  // smoothing: the Gaussian's r (0: the points' typical spacing, (box volume / count)^(1/3));
  // step: the integration's (0: r). Points farther than 3 r from a sample do not count.
  PssVolume(const std::vector<glm::vec3>& positions, const std::vector<float>& values,
            float smoothing = 0.0f, float step = 0.0f);
  size_t size() const { return points_.size(); }
  float smoothing() const { return smoothing_; }
  float reach() const { return 3.0f * smoothing_; }
  float step() const { return step_; }
  glm::vec3 lo() const { return lo_; }
  float side() const { return reach(); }
  glm::ivec3 dims() const { return dims_; }
  const std::vector<uint32_t>& start() const { return start_; }
  const std::vector<uint32_t>& order() const { return order_; }
  const std::vector<glm::vec4>& points() const { return points_; }  // position, value

 private:
  float smoothing_ = 1.0f, step_ = 1.0f;
  glm::vec3 lo_{0.0f};
  glm::ivec3 dims_{1};
  std::vector<uint32_t> start_, order_;
  std::vector<glm::vec4> points_;
};

// A transfer function's control point: a value's emitted color (linear) and extinction per unit
// length.
struct PssTransferPoint {
  float value = 0.0f;
  glm::vec3 color{1.0f};
  float extinction = 0.0f;
};
inline constexpr size_t kPssMaxTransferPoints = 8;

struct PssLight {
  glm::vec3 position{0.0f};
  float intensity = 1.0f;
};

// The surface's and the volume's part of the parameters the shaders read them by
// (shaders/pss_buffers.h): the grid, the fit's settings, kPssColors when `colors`, the volume's
// grid and settings and the transfer function (none without a volume). Throws iso::UsageError
// for more transfer points than PssParams holds.
void fillPssParams(gpu::PssParams& q, const PssSurface* surface, bool colors,
                   const PssVolume* volume, const std::vector<PssTransferPoint>& transfer);

// A point set surface among the viewer's tracer's objects (shaders/trace.h, kOptionPss), in the
// file's frame units, with the volume inside it: its parameters for the shaders (fillPssParams,
// kPssExact, and in eye.w how far rays that leave a surface skip it: 10⁻⁴ of its grid's
// diagonal).
struct PssObject {
  std::unique_ptr<PssSurface> surface;
  std::vector<glm::vec3> colors;  // linear, one a point, or none
  std::unique_ptr<PssVolume> volume;
  std::vector<PssTransferPoint> transfer;
  bool exact = false;
  // The frame's material color is the color of points without one.
  gpu::PssParams params(const gpu::FrameParams& frame) const;
};

// A picture of a point set surface (shaders/pss_trace.h): camera, lights, material.
struct PssRender {
  glm::vec3 eye{0.0f, 0.0f, 3.0f}, target{0.0f}, up{0.0f, 1.0f, 0.0f};
  float fovDegrees = 40.0f;
  int width = 512, height = 512;
  std::vector<PssLight> lights;
  glm::vec4 material{0.85f, 0.25f, 40.0f, 0.0f};  // diffuse, specular, shininess, transparency
  float reflectivity = 0.0f;                      // of the surface (mirror rays)
  glm::vec3 iors{1.5f};                           // of R, G and B (dispersion when they differ)
  float ambient = 0.15f;
  glm::vec3 color{0.75f, 0.75f, 0.72f};  // of points without a color
  glm::vec3 background{0.0f};
  bool exact = false;  // camera and refracted rays in the exact mode
  bool shadows = true;
  // The volume inside the surface (none: empty inside) and its transfer function (control points
  // by increasing value, 1 to kPssMaxTransferPoints).
  const PssVolume* volume = nullptr;
  std::vector<PssTransferPoint> transfer;
};

// The first hit of o + t d (t > 0) and the ray leaving it by Snell's law for `ior`
// (shaders/pss_trace.h): point, normal (against d) and direction.
bool pssRefract(const PssSurface& surface, const glm::vec3& o, const glm::vec3& d, float ior,
                bool exact, glm::vec3& point, glm::vec3& normal, glm::vec3& bent);

// A picture's camera rays: through pixel (x, y) along forward + sx right + sy up, sx and sy from
// -1 to 1 across the picture (right and up scaled by the field of view and the aspect).
struct PssRays {
  glm::vec3 forward{0.0f}, right{0.0f}, up{0.0f};
};
PssRays pssRays(const PssRender& render);
// The scene's size (the grid's diagonal): rays leave a surface this much times 10⁻⁴ past it.
float pssScale(const PssSurface& surface);

// The linear color a ray brings (shaders/pss_trace.h, pssRayColor) from o along d.
glm::vec3 pssRay(const PssSurface& surface, const std::vector<glm::vec3>& colors,
                 const PssRender& render, const glm::vec3& o, const glm::vec3& d);

// The picture's linear colors, rows from the top, on the CPU (every pixel with TBB); `colors` per
// point, or empty.
std::vector<glm::vec3> renderPss(const PssSurface& surface, const std::vector<glm::vec3>& colors,
                                 const PssRender& render);

}  // namespace iso::viewer
