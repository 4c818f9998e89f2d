// makeShape(): names, parameter validation, and translation by the centre.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <stdexcept>

#include "pipeline/geom/shape.h"
#include "tests/geom/shape_checks.h"

namespace iso {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

std::string errorOf(const ShapeParams& params) {
  try {
    makeShape(params);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(MakeShape, defaultsMakeTheUnitSphere) {
  const auto s = makeShape({});
  EXPECT_EQ(s->name(), "sphere");
  EXPECT_EQ(s->boundsMax(), glm::dvec3(1.0));
}

TEST(MakeShape, unknownNameListsTheKnownOnes) {
  const std::string message = errorOf({.name = "teapot"});
  EXPECT_NE(message.find("teapot"), std::string::npos) << message;
  EXPECT_NE(message.find("sphere, torus, cube, plane, sheets"), std::string::npos) << message;
}

TEST(MakeShape, rejectsBadParameters) {
  EXPECT_NE(errorOf({.name = "sphere", .radius = 0.0}).find("radius"), std::string::npos);
  EXPECT_NE(errorOf({.name = "sphere", .radius = -1.0}), "");
  EXPECT_NE(errorOf({.name = "sphere", .radius = kNaN}), "");
  EXPECT_NE(errorOf({.name = "sphere", .radius = kInf}), "");
  EXPECT_NE(errorOf({.name = "sphere", .center = {0.0, kNaN, 0.0}}).find("centre"),
            std::string::npos);
  EXPECT_NE(errorOf({.name = "torus", .minorRadius = 0.0}).find("minor"), std::string::npos);
  EXPECT_NE(errorOf({.name = "torus", .radius = 1.0, .minorRadius = 1.0}).find("smaller"),
            std::string::npos);
  EXPECT_NE(errorOf({.name = "torus", .radius = 1.0, .minorRadius = 2.0}), "");
  EXPECT_NE(errorOf({.name = "cube", .halfSize = -2.0}).find("half size"), std::string::npos);
  EXPECT_NE(errorOf({.name = "plane", .halfSize = 0.0}), "");
  EXPECT_NE(errorOf({.name = "sheets", .gap = 0.0}).find("gap"), std::string::npos);
  EXPECT_NE(errorOf({.name = "sheets", .gap = kInf}), "");
  // Parameters a shape does not use are not checked.
  EXPECT_EQ(errorOf({.name = "sphere", .minorRadius = -1.0, .halfSize = kNaN}), "");
}

// Every shape moved by a large centre (UTM-like) answers as the shape at the origin, moved.
TEST(MakeShape, everyShapeIsTranslatedByTheCenter) {
  const glm::dvec3 offset(500000.0, 4900000.0, 250.0);
  std::mt19937_64 rng(1);
  for (const char* name : {"sphere", "torus", "cube", "plane", "sheets"}) {
    SCOPED_TRACE(name);
    const auto atOrigin = makeShape({.name = name});
    const auto moved = makeShape({.name = name, .center = offset});
    EXPECT_EQ(moved->boundsMin(), atOrigin->boundsMin() + offset);
    EXPECT_EQ(moved->boundsMax(), atOrigin->boundsMax() + offset);
    EXPECT_EQ(moved->area(), atOrigin->area());
    for (int i = 0; i < 50; ++i) {
      const glm::dvec3 q = test::randomPoint(rng, glm::dvec3(-2.0), glm::dvec3(2.0));
      const ClosestPoint a = atOrigin->closest(q), b = moved->closest(q + offset);
      EXPECT_NEAR(a.distance, b.distance, 4e-9);
      EXPECT_NEAR(glm::length(a.position + offset - b.position), 0.0, 4e-9);
      EXPECT_GT(glm::dot(a.normal, b.normal), 1.0 - 1e-6);
    }
  }
}

}  // namespace
}  // namespace iso
