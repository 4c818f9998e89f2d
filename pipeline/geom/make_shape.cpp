// makeShape(): parameter validation and the table of analytic shapes by name.
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "iso/error.h"
#include "pipeline/geom/analytic.h"

namespace iso {
namespace {

void requirePositive(const std::string& shape, const char* what, double value) {
  if (std::isfinite(value) && value > 0.0) return;
  std::ostringstream message;
  message << shape << ": " << what << " must be a positive finite number, not " << value;
  throw UsageError(message.str());
}

std::unique_ptr<Shape> sphere(const ShapeParams& p) {
  requirePositive(p.name, "radius", p.radius);
  return makeSphere(p.center, p.radius);
}

std::unique_ptr<Shape> torus(const ShapeParams& p) {
  requirePositive(p.name, "radius (major)", p.radius);
  requirePositive(p.name, "minor radius", p.minorRadius);
  if (p.minorRadius >= p.radius) {
    std::ostringstream message;
    message << "torus: minor radius " << p.minorRadius << " must be smaller than the major radius "
            << p.radius << " (a ring torus)";
    throw UsageError(message.str());
  }
  return makeTorus(p.center, p.radius, p.minorRadius);
}

std::unique_ptr<Shape> cube(const ShapeParams& p) {
  requirePositive(p.name, "half size", p.halfSize);
  return makeCube(p.center, p.halfSize);
}

std::unique_ptr<Shape> plane(const ShapeParams& p) {
  requirePositive(p.name, "half size", p.halfSize);
  return makePlane(p.center, p.halfSize);
}

std::unique_ptr<Shape> sheets(const ShapeParams& p) {
  requirePositive(p.name, "half size", p.halfSize);
  requirePositive(p.name, "gap", p.gap);
  return makeSheets(p.center, p.halfSize, p.gap);
}

struct NamedShape {
  const char* name;
  std::unique_ptr<Shape> (*make)(const ShapeParams&);
};

constexpr std::array<NamedShape, 5> kShapes = {
    {{"sphere", sphere}, {"torus", torus}, {"cube", cube}, {"plane", plane}, {"sheets", sheets}}};

std::string knownNames() {
  std::string names;
  for (const NamedShape& s : kShapes) names += (names.empty() ? "" : ", ") + std::string(s.name);
  return names;
}

}  // namespace

std::unique_ptr<Shape> makeShape(const ShapeParams& params) {
  for (const NamedShape& s : kShapes) {
    if (params.name != s.name) continue;
    if (!std::isfinite(params.center.x) || !std::isfinite(params.center.y) ||
        !std::isfinite(params.center.z))
      throw UsageError(params.name + ": the centre must be finite");
    const glm::dvec3& r = params.rotation;
    if (!std::isfinite(r.x) || !std::isfinite(r.y) || !std::isfinite(r.z))
      throw UsageError(params.name + ": the rotation must be finite");
    if (r == glm::dvec3(0.0)) return s.make(params);
    return makeRotated(s.make(params), r, params.center);
  }
  throw UsageError("unknown shape '" + params.name + "' (known: " + knownNames() + ")");
}

}  // namespace iso
