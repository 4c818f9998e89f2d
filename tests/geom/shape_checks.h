// Brute-force references and checks shared by the shape tests.
#pragma once

#include <functional>
#include <glm/vec3.hpp>
#include <optional>
#include <random>
#include <vector>

#include "pipeline/geom/shape.h"

namespace iso::test {

// A signed distance written independently of the code under test (negative inside).
using SignedDistance = std::function<double(const glm::dvec3&)>;

glm::dvec3 randomDirection(std::mt19937_64& rng);
// A point uniform in the box [lower, upper].
glm::dvec3 randomPoint(std::mt19937_64& rng, const glm::dvec3& lower, const glm::dvec3& upper);

// Every sample lies on the surface (|sdf| <= tolerance), has a unit normal, and closest() of the
// sample returns (nearly) the sample itself with the same normal.
void expectSamplesOnSurface(const Shape& shape, const SignedDistance& sdf, int count,
                            double tolerance, uint64_t seed = 1);

// The closest point is exact: it lies on the surface (by the independent sdf), its distance is
// |query - position| and |sdf(query)|, it is no farther than any of `surface` (dense samples), and
// for a smooth surface (isSmooth) query - position is along the normal.
void expectClosestIsExact(const Shape& shape, const SignedDistance& sdf, const glm::dvec3& query,
                          const std::vector<glm::dvec3>& surface, bool isSmooth);

// The first sign change of sdf along the ray within (tMin, tMax), found by marching with `step`
// and bisecting to the last bit.
std::optional<double> marchRay(const SignedDistance& sdf, const glm::dvec3& origin,
                               const glm::dvec3& direction, double tMin, double tMax, double step);

// Pearson's statistic Σ (observed - expected)² / expected.
double chiSquare(const std::vector<double>& observed, const std::vector<double>& expected);

std::vector<glm::dvec3> samplePositions(const Shape& shape, int count, uint64_t seed);

}  // namespace iso::test
