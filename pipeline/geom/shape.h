// Surfaces with a known answer: the ground truth that `iso gen` samples and `iso eval` measures
// against. Analytic shapes (sphere, torus, cube, plane, sheets) and triangle meshes share one
// interface: sampling by area, closest point with normal, and ray intersection.
//
// Threading: const member functions may be called from many threads at once.
#pragma once

#include <glm/vec3.hpp>
#include <memory>
#include <optional>
#include <random>
#include <string>

#include "iso/error.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct SurfacePoint {
  glm::dvec3 position;
  glm::dvec3 normal;  // unit; outward for closed shapes, the oriented side for open ones
};

struct ClosestPoint {
  glm::dvec3 position;
  glm::dvec3 normal;  // unit normal of the surface at position
  double distance;    // |query - position|, >= 0
};

class Shape {
 public:
  virtual ~Shape() = default;
  virtual std::string name() const = 0;
  virtual double area() const = 0;
  virtual bool isClosed() const = 0;  // a closed surface bounds a volume
  // Axis-aligned bounds of the surface.
  virtual glm::dvec3 boundsMin() const = 0;
  virtual glm::dvec3 boundsMax() const = 0;
  // A point distributed uniformly by area, with its normal.
  virtual SurfacePoint sample(std::mt19937_64& rng) const = 0;
  virtual ClosestPoint closest(const glm::dvec3& query) const = 0;
  // The closest point when it is at most maxDistance away, else none (meshes prune by it).
  virtual std::optional<ClosestPoint> closestWithin(const glm::dvec3& query,
                                                    double maxDistance) const {
    const ClosestPoint c = closest(query);
    if (c.distance <= maxDistance) return c;
    return std::nullopt;
  }
  // The smallest t in (tMin, tMax) with origin + t·direction on the surface, if any.
  virtual std::optional<double> intersect(const glm::dvec3& origin, const glm::dvec3& direction,
                                          double tMin, double tMax) const = 0;
};

// Parameters of the analytic shapes; the defaults are those of `iso gen` and `iso eval`.
struct ShapeParams {
  std::string name = "sphere";  // sphere, torus, cube, plane, sheets
  glm::dvec3 center{0.0};       // added to every shape (also the place of large offsets)
  double radius = 1.0;          // sphere radius; torus major radius
  double minorRadius = 0.35;    // torus tube radius
  double halfSize = 1.0;        // cube half edge; plane and sheets half extent in x and y
  double gap = 0.02;            // sheets: distance between the two sheets (z = ±gap/2)
  glm::dvec3 rotation{0.0};     // degrees about x, then y, then z, around the centre
};

// Make an analytic shape; throws UsageError for an unknown name or bad parameters.
// cube: axis-aligned, sharp edges. plane: the square |x|,|y| <= halfSize at z = 0, normal +z, open
// boundary. sheets: two such squares at z = +gap/2 (normal +z) and z = -gap/2 (normal -z), the two
// sides of a thin slab without its rim (open).
// A rotation (params.rotation) turns the shape about its centre.
std::unique_ptr<Shape> makeShape(const ShapeParams& params);

// The shape turned about `pivot` by `degrees` about the x, then the y, then the z axis.
std::unique_ptr<Shape> makeRotated(std::unique_ptr<Shape> shape, const glm::dvec3& degrees,
                                   const glm::dvec3& pivot);

// A triangle mesh as a shape (closest point and ray queries through a bounding volume hierarchy).
// isClosed() is true when every edge is shared by exactly two triangles (a triangle with a repeated
// vertex index has no edges). Normals are the triangles' geometric normals (winding order).
// Zero-area triangles are never sampled nor met by queries; closest() of a non-finite query has a
// NaN distance. Throws UsageError for an index out of range, a non-finite vertex, or no
// triangle of positive area. Builds with TBB in about a second per million triangles.
std::unique_ptr<Shape> makeMeshShape(TriangleMesh mesh);

}  // namespace iso
