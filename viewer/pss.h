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
#include <vector>

namespace iso::viewer {

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

  size_t size() const { return positions_.size(); }
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
  // Cells: each point once (points_), and each trust region reaching in (reach_).
  struct Grid {
    glm::vec3 lo{0.0f};
    float side = 1.0f;
    glm::ivec3 dims{1};
    std::vector<uint32_t> pointStart, points, reachStart, reach;
  };
  glm::ivec3 cellOf(const glm::vec3& p) const;
  size_t cellIndex(const glm::ivec3& c) const;
  bool fast(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax, PssHit& hit) const;
  void neighbours(const glm::vec3& x, float radius, std::vector<uint32_t>& out) const;

  std::vector<glm::vec3> positions_, normals_;
  std::vector<float> h_;
  PssOptions options_;
  std::vector<PssPatch> patches_;
  Grid grid_;
};

}  // namespace iso::viewer
