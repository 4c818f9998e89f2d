// The analytic shapes behind makeShape(), one per file. Parameters are validated by makeShape();
// these constructors assume finite, positive sizes and a minor radius below the major one.
#pragma once

#include <glm/vec3.hpp>
#include <memory>

#include "pipeline/geom/shape.h"

namespace iso {

std::unique_ptr<Shape> makeSphere(const glm::dvec3& center, double radius);
// A ring torus around the z axis through center.
std::unique_ptr<Shape> makeTorus(const glm::dvec3& center, double majorRadius, double minorRadius);
std::unique_ptr<Shape> makeCube(const glm::dvec3& center, double halfSize);
// The square |x|,|y| <= halfSize at z = 0 with normal +z.
std::unique_ptr<Shape> makePlane(const glm::dvec3& center, double halfSize);
// Squares at z = +gap/2 (normal +z) and z = -gap/2 (normal -z).
std::unique_ptr<Shape> makeSheets(const glm::dvec3& center, double halfSize, double gap);

}  // namespace iso
