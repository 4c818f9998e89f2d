// Triangle meshes built in code for the geometry tests and the benchmark.
#pragma once

#include <glm/vec3.hpp>

#include "pipeline/io/point_cloud.h"

namespace iso::test {

// The icosahedron subdivided `subdivisions` times with vertices pushed onto the sphere: closed,
// 20·4^subdivisions counter-clockwise (outward) triangles, every edge shared by two.
TriangleMesh icosphere(int subdivisions, double radius = 1.0, glm::dvec3 center = glm::dvec3(0.0));

// An icosphere with smooth radial bumps of relative height `amplitude`: a closed surface with
// curvature everywhere, like a scanned object.
TriangleMesh bumpySphere(int subdivisions, double amplitude);

// The height field z = 0.2 sin(3x) cos(2y) over [-1, 1]² as 2·n² triangles facing +z: open.
TriangleMesh wavyGrid(int n);

}  // namespace iso::test
