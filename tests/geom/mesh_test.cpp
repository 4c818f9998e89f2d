// The mesh shape against exhaustive searches over its triangles with independent formulas.
#include <tbb/global_control.h>

#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "pipeline/geom/shape.h"
#include "pipeline/geom/triangle.h"
#include "tests/geom/meshes.h"
#include "tests/geom/shape_checks.h"

namespace iso {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

struct Corners {
  glm::dvec3 a, b, c;
};

Corners corners(const TriangleMesh& mesh, size_t i) {
  const auto& t = mesh.triangles[i];
  return {mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]};
}

glm::dvec3 closestOnSegment(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b) {
  const double t = glm::dot(p - a, b - a) / glm::dot(b - a, b - a);
  return a + std::clamp(t, 0.0, 1.0) * (b - a);
}

// Reference: the projection onto the plane if it falls inside (edge tests by orientation), else
// the nearest of the three edges' closest points.
glm::dvec3 referenceClosest(const glm::dvec3& p, const Corners& t) {
  const glm::dvec3 n = glm::cross(t.b - t.a, t.c - t.a);
  const glm::dvec3 projected = p - glm::dot(p - t.a, n) / glm::dot(n, n) * n;
  if (glm::dot(glm::cross(t.b - t.a, projected - t.a), n) >= 0.0 &&
      glm::dot(glm::cross(t.c - t.b, projected - t.b), n) >= 0.0 &&
      glm::dot(glm::cross(t.a - t.c, projected - t.c), n) >= 0.0)
    return projected;
  glm::dvec3 best = closestOnSegment(p, t.a, t.b);
  for (const glm::dvec3& q : {closestOnSegment(p, t.b, t.c), closestOnSegment(p, t.c, t.a)})
    if (glm::length(p - q) < glm::length(p - best)) best = q;
  return best;
}

// Reference ray hit: Möller and Trumbore (1997), both sides.
std::optional<double> referenceRay(const glm::dvec3& o, const glm::dvec3& d, const Corners& t) {
  const glm::dvec3 e1 = t.b - t.a, e2 = t.c - t.a, pv = glm::cross(d, e2);
  const double det = glm::dot(e1, pv);
  if (det == 0.0) return std::nullopt;
  const glm::dvec3 tv = o - t.a;
  const double u = glm::dot(tv, pv) / det;
  const glm::dvec3 qv = glm::cross(tv, e1);
  const double v = glm::dot(d, qv) / det;
  if (u < 0.0 || v < 0.0 || u + v > 1.0) return std::nullopt;
  return glm::dot(e2, qv) / det;
}

struct BruteClosest {
  double distance = kInf;
  glm::dvec3 position{0.0};
  glm::dvec3 normal{0.0};
};

BruteClosest bruteClosest(const TriangleMesh& mesh, const glm::dvec3& q) {
  BruteClosest best;
  for (size_t i = 0; i < mesh.triangles.size(); ++i) {
    const Corners t = corners(mesh, i);
    if (glm::length(glm::cross(t.b - t.a, t.c - t.a)) == 0.0) continue;
    const glm::dvec3 p = referenceClosest(q, t);
    if (glm::length(q - p) < best.distance)
      best = {glm::length(q - p), p, glm::normalize(glm::cross(t.b - t.a, t.c - t.a))};
  }
  return best;
}

double meshArea(const TriangleMesh& mesh) {
  double area = 0.0;
  for (size_t i = 0; i < mesh.triangles.size(); ++i) {
    const Corners t = corners(mesh, i);
    area += 0.5 * glm::length(glm::cross(t.b - t.a, t.c - t.a));
  }
  return area;
}

// Where several points are equally near (a query at the centre of a symmetric mesh), only the
// distance is compared.
void expectClosestMatchesBruteForce(const TriangleMesh& mesh, const Shape& shape,
                                    const glm::dvec3& q, bool isUnique = true) {
  const BruteClosest expected = bruteClosest(mesh, q);
  const ClosestPoint c = shape.closest(q);
  SCOPED_TRACE(testing::Message() << "query " << q.x << " " << q.y << " " << q.z);
  EXPECT_NEAR(c.distance, expected.distance, 1e-13 * (1.0 + expected.distance));
  EXPECT_NEAR(c.distance, glm::length(q - c.position), 1e-14 * (1.0 + c.distance));
  // Ties (a point nearest to a shared edge or vertex) may pick another triangle of the same point.
  if (isUnique) {
    EXPECT_NEAR(glm::length(c.position - expected.position), 0.0, 1e-9);
  }
  EXPECT_NEAR(glm::length(c.normal), 1.0, 1e-14);
}

TEST(Triangle, closestPointMatchesProjectionOrEdgesInEveryRegion) {
  std::mt19937_64 rng(1);
  for (int i = 0; i < 20000; ++i) {
    // Arbitrary triangles, obtuse and thin ones included, and queries all around them.
    const Corners t{test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0)),
                    test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0)),
                    test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0))};
    const glm::dvec3 q = test::randomPoint(rng, glm::dvec3(-2.0), glm::dvec3(2.0));
    const glm::dvec3 p = closestPointOnTriangle(q, t.a, t.b, t.c);
    const glm::dvec3 expected = referenceClosest(q, t);
    ASSERT_NEAR(glm::length(q - p), glm::length(q - expected), 1e-13) << "triangle " << i;
    ASSERT_NEAR(glm::length(p - expected), 0.0, 1e-7) << "triangle " << i;
  }
}

TEST(Triangle, watertightRayMatchesMollerTrumbore) {
  std::mt19937_64 rng(2);
  int hits = 0;
  for (int i = 0; i < 20000; ++i) {
    const Corners t{test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0)),
                    test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0)),
                    test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0))};
    const glm::dvec3 o = test::randomPoint(rng, glm::dvec3(-3.0), glm::dvec3(3.0));
    const glm::dvec3 d = test::randomPoint(rng, glm::dvec3(-1.0), glm::dvec3(1.0)) - o;
    const std::optional<double> expected = referenceRay(o, d, t);
    const std::optional<double> hit =
        intersectTriangle(ShearedRay(o, d), t.a, t.b, t.c, -kInf, kInf);
    ASSERT_EQ(hit.has_value(), expected.has_value()) << "ray " << i;
    if (hit) {
      ASSERT_NEAR(*hit, *expected, 1e-12 * (1.0 + std::abs(*expected))) << "ray " << i;
      ++hits;
    }
  }
  EXPECT_GT(hits, 1000);
}

TEST(MeshShape, icosphereIsClosedWithTheSumOfItsTriangleAreas) {
  const TriangleMesh mesh = test::icosphere(3, 2.0, glm::dvec3(1.0, 2.0, 3.0));
  const auto shape = makeMeshShape(mesh);
  EXPECT_EQ(shape->name(), "mesh");
  EXPECT_TRUE(shape->isClosed());
  EXPECT_NEAR(shape->area(), meshArea(mesh), 1e-13 * meshArea(mesh));
  EXPECT_LT(shape->area(), 4.0 * std::numbers::pi * 4.0);
  EXPECT_GT(shape->area(), 0.99 * 4.0 * std::numbers::pi * 4.0);
  EXPECT_EQ(shape->boundsMin(), glm::dvec3(-1.0, 0.0, 1.0));
  EXPECT_EQ(shape->boundsMax(), glm::dvec3(3.0, 4.0, 5.0));
}

TEST(MeshShape, openOrNonManifoldMeshesAreNotClosed) {
  EXPECT_FALSE(makeMeshShape(test::wavyGrid(8))->isClosed());
  TriangleMesh holed = test::icosphere(2);
  holed.triangles.pop_back();
  EXPECT_FALSE(makeMeshShape(holed)->isClosed());
  // An edge shared by three triangles: a fin on a closed surface.
  TriangleMesh finned = test::icosphere(2);
  const auto [a, b, c] = finned.triangles[0];
  finned.vertices.push_back(glm::dvec3(3.0, 3.0, 3.0));
  finned.triangles.push_back({a, b, uint32_t(finned.vertices.size() - 1)});
  finned.triangles.push_back({b, a, uint32_t(finned.vertices.size() - 1)});
  EXPECT_FALSE(makeMeshShape(finned)->isClosed());
}

TEST(MeshShape, samplesLieOnTheMeshWithTheirTriangleNormals) {
  const TriangleMesh mesh = test::bumpySphere(3, 0.1);
  const auto shape = makeMeshShape(mesh);
  std::mt19937_64 rng(3);
  for (int i = 0; i < 2000; ++i) {
    const SurfacePoint s = shape->sample(rng);
    const ClosestPoint c = shape->closest(s.position);
    ASSERT_LE(c.distance, 1e-15) << "sample " << i;
    ASSERT_GT(glm::dot(c.normal, s.normal), 1.0 - 1e-12) << "sample " << i;
    ASSERT_GT(glm::dot(s.normal, s.position), 0.0) << "outward normals";
    ASSERT_NEAR(bruteClosest(mesh, s.position).distance, 0.0, 1e-15);
  }
}

// Two triangles of areas 1 and 3: samples split 1:3, and within a triangle the corner triangle cut
// by the edge midpoints holds a quarter of them.
TEST(MeshShape, samplingFollowsTriangleAreasAndIsUniformWithinTriangles) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {2, 0, 0}, {0, 1, 0}, {0, 0, 5}, {2, 0, 5}, {0, 3, 5}};
  mesh.triangles = {{0, 1, 2}, {3, 4, 5}};
  const auto shape = makeMeshShape(mesh);
  EXPECT_DOUBLE_EQ(shape->area(), 4.0);
  std::mt19937_64 rng(4);
  constexpr int kSamples = 100000;
  std::vector<double> counts(4, 0.0);  // small near/far from vertex 0, large near/far
  for (int i = 0; i < kSamples; ++i) {
    const glm::dvec3 p = shape->sample(rng).position;
    const bool isLarge = p.z > 2.5;
    // Inside the corner triangle at vertex 0 (half-size copy) iff x/2 + y/h < 1/2.
    const bool isCorner = p.x / 2.0 + p.y / (isLarge ? 3.0 : 1.0) < 0.5;
    counts[2 * isLarge + !isCorner] += 1.0;
  }
  const std::vector<double> expected = {kSamples * 0.25 * 0.25, kSamples * 0.25 * 0.75,
                                        kSamples * 0.75 * 0.25, kSamples * 0.75 * 0.75};
  // 3 degrees of freedom: P(chi² > 20) ≈ 2e-4.
  EXPECT_LT(test::chiSquare(counts, expected), 20.0);
}

TEST(MeshShape, closestPointMatchesExhaustiveSearch) {
  const TriangleMesh mesh = test::bumpySphere(5, 0.1);  // 20480 triangles: a parallel build
  const auto shape = makeMeshShape(mesh);
  std::mt19937_64 rng(5);
  for (int i = 0; i < 150; ++i) {
    const SurfacePoint s = shape->sample(rng);
    // Near the surface on both sides, within the ball, and far away.
    const double offset = i % 3 == 0 ? 0.01 : i % 3 == 1 ? -0.3 : 2.0;
    expectClosestMatchesBruteForce(mesh, *shape, s.position + offset * test::randomDirection(rng));
  }
  expectClosestMatchesBruteForce(mesh, *shape, glm::dvec3(0.0), false);
  expectClosestMatchesBruteForce(mesh, *shape, glm::dvec3(100.0, -50.0, 3.0));
}

TEST(MeshShape, openMeshClosestPointMatchesExhaustiveSearch) {
  const TriangleMesh mesh = test::wavyGrid(40);
  const auto shape = makeMeshShape(mesh);
  std::mt19937_64 rng(6);
  for (int i = 0; i < 150; ++i)
    expectClosestMatchesBruteForce(
        mesh, *shape,
        test::randomPoint(rng, glm::dvec3(-1.5, -1.5, -0.5), glm::dvec3(1.5, 1.5, 0.5)));
}

TEST(MeshShape, rayHitsMatchExhaustiveSearchOverAllTriangles) {
  const TriangleMesh mesh = test::bumpySphere(4, 0.15);
  const auto shape = makeMeshShape(mesh);
  std::mt19937_64 rng(7);
  int hits = 0;
  for (int i = 0; i < 400; ++i) {
    const glm::dvec3 o = test::randomPoint(rng, glm::dvec3(-1.6), glm::dvec3(1.6));
    // Half of the rays aim at the surface; directions are not unit.
    glm::dvec3 d = 0.25 * test::randomDirection(rng);
    if (i % 2 == 0) d = shape->sample(rng).position - o;
    const double tMin = i % 5 == 0 ? 0.3 : 0.0, tMax = i % 7 == 0 ? 1.0 : kInf;
    std::optional<double> expected;
    for (size_t k = 0; k < mesh.triangles.size(); ++k) {
      const Corners t = corners(mesh, k);
      const std::optional<double> h =
          intersectTriangle(ShearedRay(o, d), t.a, t.b, t.c, tMin, tMax);
      if (h && (!expected || *h < *expected)) expected = h;
    }
    const std::optional<double> hit = shape->intersect(o, d, tMin, tMax);
    ASSERT_EQ(hit.has_value(), expected.has_value()) << "ray " << i;
    if (!hit) continue;
    EXPECT_EQ(*hit, *expected) << "ray " << i;
    ++hits;
  }
  EXPECT_GT(hits, 200);
}

// Rays from the centre through every vertex and every edge midpoint of a closed mesh must hit: the
// watertight test leaves no crack between neighbours.
TEST(MeshShape, raysThroughSharedVerticesAndEdgesNeverLeak) {
  const TriangleMesh mesh = test::icosphere(3);
  const auto shape = makeMeshShape(mesh);
  for (const glm::dvec3& v : mesh.vertices)
    EXPECT_TRUE(shape->intersect(glm::dvec3(0.0), v, 0.0, kInf)) << v.x << " " << v.y << " " << v.z;
  for (const auto& t : mesh.triangles) {
    for (int i = 0; i < 3; ++i) {
      const glm::dvec3 mid = 0.5 * (mesh.vertices[t[i]] + mesh.vertices[t[(i + 1) % 3]]);
      EXPECT_TRUE(shape->intersect(glm::dvec3(0.0), mid, 0.0, kInf));
      // Also from outside, inwards.
      EXPECT_TRUE(shape->intersect(3.0 * mid, -mid, 0.0, kInf));
    }
  }
}

// Zero-area triangles are neither sampled nor met by queries. Those with a repeated index are
// points or segments without edges; others (collinear corners) still have three edges.
TEST(MeshShape, degenerateTrianglesChangeNothing) {
  TriangleMesh mesh = test::icosphere(2);
  const auto clean = makeMeshShape(mesh);
  const uint32_t n = uint32_t(mesh.vertices.size());
  mesh.vertices.insert(mesh.vertices.end(), {{0.5, 0.0, 0.0}, {0.75, 0.0, 0.0}, {1.0, 0.0, 0.0}});
  mesh.triangles.insert(mesh.triangles.begin() + 7, {0, 0, 1});
  mesh.triangles.push_back({2, 2, 2});
  mesh.triangles.push_back({n, n + 1, n + 2});
  const auto withDegenerate = makeMeshShape(mesh);
  EXPECT_DOUBLE_EQ(withDegenerate->area(), clean->area());
  EXPECT_EQ(withDegenerate->boundsMax(), clean->boundsMax());
  EXPECT_FALSE(withDegenerate->isClosed());
  std::mt19937_64 rng(8), rngClean(8);
  for (int i = 0; i < 1000; ++i) {
    const SurfacePoint s = withDegenerate->sample(rng);
    ASSERT_LE(withDegenerate->closest(s.position).distance, 1e-15);
    const glm::dvec3 q = 1.3 * test::randomDirection(rngClean);
    ASSERT_EQ(withDegenerate->closest(q).distance, clean->closest(q).distance);
    ASSERT_EQ(withDegenerate->intersect(q, -q, 0.0, kInf), clean->intersect(q, -q, 0.0, kInf));
  }
  TriangleMesh onlyRepeated = test::icosphere(1);
  onlyRepeated.triangles.push_back({3, 3, 4});
  EXPECT_TRUE(makeMeshShape(onlyRepeated)->isClosed());
}

// Many triangles with one centroid leave SAH nothing to split: the median split takes over.
TEST(MeshShape, coincidentTrianglesAreSplitAndFound) {
  TriangleMesh mesh;
  mesh.vertices = {{-1, -1, 0}, {1, -1, 0}, {0, 1, 0}};
  for (int i = 0; i < 1000; ++i) mesh.triangles.push_back({0, 1, 2});
  const auto shape = makeMeshShape(mesh);
  EXPECT_DOUBLE_EQ(shape->area(), 2000.0);
  EXPECT_FALSE(shape->isClosed());
  EXPECT_NEAR(shape->closest(glm::dvec3(0.0, 0.0, 2.0)).distance, 2.0, 1e-15);
  EXPECT_NEAR(*shape->intersect(glm::dvec3(0.0, 0.0, 2.0), glm::dvec3(0.0, 0.0, -1.0), 0.0, kInf),
              2.0, 1e-15);
}

TEST(MeshShape, rejectsInvalidMeshes) {
  TriangleMesh outOfRange = test::icosphere(0);
  outOfRange.triangles.push_back({0, 1, 99});
  EXPECT_THROW(makeMeshShape(outOfRange), std::invalid_argument);
  TriangleMesh notFinite = test::icosphere(0);
  notFinite.vertices[3].y = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(makeMeshShape(notFinite), std::invalid_argument);
  TriangleMesh flat;
  flat.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  flat.triangles = {{0, 1, 2}};
  EXPECT_THROW(makeMeshShape(flat), std::invalid_argument);
  EXPECT_THROW(makeMeshShape(TriangleMesh{}), std::invalid_argument);
}

// The tree is built by parallel tasks; its answers must not depend on the number of threads.
TEST(MeshShape, answersDoNotDependOnTheThreadCount) {
  const TriangleMesh mesh = test::bumpySphere(6, 0.1);
  std::unique_ptr<Shape> serial;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    serial = makeMeshShape(mesh);
  }
  const auto parallel = makeMeshShape(mesh);
  std::mt19937_64 rng(9);
  for (int i = 0; i < 2000; ++i) {
    const glm::dvec3 q = test::randomPoint(rng, glm::dvec3(-1.5), glm::dvec3(1.5));
    const ClosestPoint a = serial->closest(q), b = parallel->closest(q);
    ASSERT_EQ(a.position, b.position);
    ASSERT_EQ(a.normal, b.normal);
    ASSERT_EQ(serial->intersect(q, -q, 0.0, kInf), parallel->intersect(q, -q, 0.0, kInf));
  }
}

// World coordinates far from the origin keep their precision.
TEST(MeshShape, largeCoordinatesKeepMillimetreDetail) {
  const glm::dvec3 center(512345.678, 4918765.432, 321.0);
  const TriangleMesh mesh = test::icosphere(4, 10.0, center);
  const auto shape = makeMeshShape(mesh);
  std::mt19937_64 rng(10);
  for (int i = 0; i < 50; ++i) {
    const glm::dvec3 q = center + 10.003 * test::randomDirection(rng);
    const BruteClosest expected = bruteClosest(mesh, q);
    EXPECT_NEAR(shape->closest(q).distance, expected.distance, 1e-8);
    const std::optional<double> hit = shape->intersect(center, q - center, 0.0, kInf);
    ASSERT_TRUE(hit);
    EXPECT_LT(shape->closest(center + *hit * (q - center)).distance, 1e-8);
  }
}

}  // namespace
}  // namespace iso
