// The stages one by one, against brute force or analytic answers.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <numeric>
#include <optional>
#include <random>

#include "pipeline/base/options.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/output/chunks.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

PointCloud randomCloud(size_t n, uint64_t seed) {
  PointCloud cloud;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (size_t i = 0; i < n; ++i) cloud.positions.push_back({u(rng), u(rng), 0.3 * u(rng)});
  return cloud;
}

PointSet prepared(const PointCloud& cloud) {
  PointSet points = makePointSet(cloud, chooseFrame(cloud));
  sortByKey(points);
  mergeDuplicates(points);
  return points;
}

TEST(Morton, encodeAndDecodeAreInverse) {
  std::mt19937 rng(5);
  for (int i = 0; i < 10000; ++i) {
    const uint32_t x = rng() & 0x1fffff, y = rng() & 0x1fffff, z = rng() & 0x1fffff;
    const auto c = mortonDecode(mortonEncode(x, y, z));
    EXPECT_EQ(c, (std::array<uint32_t, 3>{x, y, z}));
  }
  EXPECT_EQ(mortonEncode(1, 0, 0), 1u);
  EXPECT_EQ(mortonEncode(0, 1, 0), 2u);
  EXPECT_EQ(mortonEncode(0, 0, 1), 4u);
  EXPECT_EQ(mortonEncode(2, 0, 0), 8u);
}

TEST(Frame, sortedOrderIsAStableSortByKey) {
  std::mt19937_64 rng(5);
  // Sizes around the block and small-bucket thresholds; keys from all 63 bits, from few bits
  // (many equal keys: stability shows), and all equal.
  for (const size_t n : {size_t{0}, size_t{1}, size_t{70}, size_t{65536 * 3 + 17}}) {
    for (const int bits : {63, 5, 0}) {
      std::vector<uint64_t> keys(n);
      for (uint64_t& k : keys) k = bits == 0 ? 42 : rng() >> (64 - bits);
      std::vector<uint32_t> expected(n);
      std::iota(expected.begin(), expected.end(), 0u);
      std::stable_sort(expected.begin(), expected.end(),
                       [&](uint32_t a, uint32_t b) { return keys[a] < keys[b]; });
      EXPECT_EQ(sortedOrder(keys), expected) << n << " keys of " << bits << " bits";
    }
  }
}

TEST(Frame, pointsAreInsideTheCubeAndSortedByKey) {
  PointCloud cloud = randomCloud(20000, 1);
  for (glm::dvec3& p : cloud.positions) p += glm::dvec3(512345.6, 4918000.2, 1200.0);  // UTM-like
  const Frame frame = chooseFrame(cloud);
  const PointSet points = prepared(cloud);
  ASSERT_EQ(points.size(), cloud.size());
  EXPECT_TRUE(std::is_sorted(points.key.begin(), points.key.end()));
  for (size_t i = 0; i < points.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_GT(points.position[i][a], 0.0f);
      EXPECT_LT(points.position[i][a], 1.0f);
    }
    const glm::dvec3 back = glm::dvec3(points.position[i]) * frame.size +
                            glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]);
    EXPECT_LT(glm::length(back - cloud.positions[points.source[i]]), 1e-6);  // float in frame units
  }
}

TEST(Frame, exactDuplicatesMergeIntoWeightedPoints) {
  PointCloud cloud = randomCloud(1000, 2);
  cloud.normals.assign(cloud.size(), glm::vec3(0, 0, 1));
  for (size_t i = 0; i < 300; ++i) {
    cloud.positions.push_back(cloud.positions[i]);
    cloud.normals.push_back(glm::vec3(1, 0, 0));
  }
  PointSet points = makePointSet(cloud, chooseFrame(cloud));
  sortByKey(points);
  EXPECT_EQ(mergeDuplicates(points), 300u);
  ASSERT_EQ(points.size(), 1000u);
  float weight = 0.0f;
  for (size_t i = 0; i < points.size(); ++i) {
    weight += points.weight[i];
    if (points.weight[i] == 2.0f) {
      EXPECT_NEAR(glm::length(points.normal[i] - glm::normalize(glm::vec3(1, 0, 1))), 0.0f, 1e-6f);
    }
  }
  EXPECT_EQ(weight, 1300.0f);
}

TEST(Radii, nearestNeighboursMatchBruteForce) {
  PointSet points = prepared(randomCloud(3000, 3));
  const PointIndex tree(points.position);
  const Neighbors neighbors = findNeighbors(points, tree, 10);
  estimateRadii(points, neighbors);
  for (size_t i = 0; i < points.size(); i += 37) {
    std::vector<float> d;
    for (size_t j = 0; j < points.size(); ++j)
      if (j != i) d.push_back(glm::length(points.position[i] - points.position[j]));
    std::sort(d.begin(), d.end());
    for (int k = 0; k < 10; ++k)
      EXPECT_FLOAT_EQ(neighbors.distance[i * 10 + size_t(k)], d[size_t(k)]);
    EXPECT_LE(points.radius[i], d[9]);
  }
}

TEST(Normals, pcaRecoversAPlaneAndPropagationOrientsASphere) {
  PointCloud plane = randomCloud(5000, 4);
  for (glm::dvec3& p : plane.positions) p.z = 0.3 * p.x - 0.2 * p.y;
  PointSet points = prepared(plane);
  const PointIndex tree(points.position);
  const Neighbors neighbors = findNeighbors(points, tree, 10);
  EXPECT_EQ(estimateNormals(points, neighbors), points.size());
  const glm::vec3 truth = glm::normalize(glm::vec3(-0.3f, 0.2f, 1.0f));
  for (const glm::vec3& n : points.normal) EXPECT_GT(std::abs(glm::dot(n, truth)), 0.99999f);

  PointSet sphere = prepared(test::scanOf("sphere", 50000, false));
  const PointIndex sphereTree(sphere.position);
  const Neighbors sphereNeighbors = findNeighbors(sphere, sphereTree, 10);
  estimateNormals(sphere, sphereNeighbors);
  orientNormals(sphere, sphereNeighbors, OrientMode::Auto, std::vector<uint8_t>(sphere.size(), 1));
  size_t outward = 0;
  for (size_t i = 0; i < sphere.size(); ++i)
    outward += glm::dot(sphere.normal[i], sphere.position[i] - glm::vec3(0.5f)) > 0.0f ? 1 : 0;
  EXPECT_EQ(outward, sphere.size());
}

// The fraction of normals pointing out of a sphere or torus centred in the frame (the torus' core
// circle lies in z = 0.5; its radius is the points' mean distance from the axis).
double outwardFraction(const PointSet& points, bool torus) {
  double ring = 0.0;
  for (const glm::vec3& p : points.position)
    ring += std::hypot(p.x - 0.5, p.y - 0.5) / double(points.size());
  size_t outward = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::vec3 p = points.position[i] - glm::vec3(0.5f);
    glm::vec3 centre(0.0f);
    if (torus) centre = glm::normalize(glm::vec3(p.x, p.y, 0.0f)) * float(ring);
    outward += glm::dot(points.normal[i], p - centre) > 0.0f ? 1 : 0;
  }
  return double(outward) / double(points.size());
}

TEST(Normals, orientationInManySmallBlocksAgreesAcrossTheirBoundaries) {
  // From 1 block to a few thousand: each block is oriented on its own (most lower blocks start
  // from a wrong "top faces up" guess), then whole components flip to agree with their
  // neighbours. Every normal of a sphere and of a torus must point out.
  for (const char* shape : {"sphere", "torus"}) {
    PointSet base = prepared(test::scanOf(shape, 60000, false));
    const PointIndex tree(base.position);
    const Neighbors neighbors = findNeighbors(base, tree, 10);
    estimateNormals(base, neighbors);
    for (size_t blockPoints : {size_t{1} << 20, size_t{4096}, size_t{300}, size_t{20}}) {
      PointSet points = base;
      orientNormals(points, neighbors, OrientMode::Auto, std::vector<uint8_t>(points.size(), 1),
                    blockPoints);
      EXPECT_EQ(outwardFraction(points, shape == std::string("torus")), 1.0)
          << shape << ", blocks of " << blockPoints;
    }
  }
}

TEST(Normals, inputNormalsFixTheOrientationOfTheBlocksTheyReach) {
  // A torus whose input normals point inward on the first 1% of the points (in key order) and
  // are missing elsewhere: the anchored component decides, so every normal points inward.
  PointSet points = prepared(test::scanOf("torus", 40000, true));
  std::vector<uint8_t> estimated(points.size(), 1);
  for (size_t i = 0; i < points.size(); ++i) {
    if (i < points.size() / 100) {
      points.normal[i] = -points.normal[i];
      estimated[i] = 0;
    } else {
      points.normal[i] = glm::vec3(0.0f);
    }
  }
  const PointIndex tree(points.position);
  const Neighbors neighbors = findNeighbors(points, tree, 10);
  estimateNormals(points, neighbors);
  orientNormals(points, neighbors, OrientMode::Auto, estimated, 500);
  EXPECT_EQ(outwardFraction(points, true), 0.0);
}

struct Evaluated {
  PointSet points;
  std::unique_ptr<PointIndex> tree;
};

Evaluated withRadii(const PointCloud& cloud) {
  Evaluated e{prepared(cloud), nullptr};
  e.tree = std::make_unique<PointIndex>(e.points.position);
  estimateRadii(e.points, findNeighbors(e.points, *e.tree, 10));
  return e;
}

TEST(SignedDistance, isExactForAPlaneWithEitherFit) {
  PointCloud plane = randomCloud(20000, 6);
  for (glm::dvec3& p : plane.positions) p.z = 0.0;
  plane.normals.assign(plane.size(), glm::vec3(0, 0, 1));
  const Evaluated e = withRadii(plane);
  const double z = e.points.position[0].z;
  for (FitMode fit : {FitMode::Plane, FitMode::Sphere}) {
    const SdfEvaluator sdf(e.points, *e.tree, 1.0, fit);
    for (double offset : {-0.1, -0.01, 0.0, 0.003, 0.05, 0.2}) {
      const CornerSample s = sdf.evaluate({0.5, 0.45, z + offset}, 0.0f);
      EXPECT_NEAR(s.distance, offset, 1e-6) << "offset " << offset;
      EXPECT_NEAR(s.normal.z, 1.0f, 1e-6f);
    }
  }
}

TEST(SignedDistance, sphereFitRemovesTheCurvatureBiasOfThePlaneFit) {
  const Evaluated e = withRadii(test::scanOf("sphere", 100000));
  const Frame frame = chooseFrame(test::scanOf("sphere", 100000));
  const SdfEvaluator plane(e.points, *e.tree, 1.0, FitMode::Plane),
      sphere(e.points, *e.tree, 1.0, FitMode::Sphere);
  const glm::dvec3 center = toFrame(glm::dvec3(0.0), frame);
  double planeError = 0.0, sphereError = 0.0;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  for (int i = 0; i < 500; ++i) {
    const glm::dvec3 dir = glm::normalize(glm::dvec3(g(rng), g(rng), g(rng)));
    const double r = 1.0 + 0.02 * (double(i % 11) - 5.0) / 5.0;  // within 2 % of the surface
    const glm::dvec3 q = center + dir * r / frame.size;
    const double truth = (r - 1.0) / frame.size;
    planeError = std::max(planeError, std::abs(plane.evaluate(q, 0.0f).distance - truth));
    sphereError = std::max(sphereError, std::abs(sphere.evaluate(q, 0.0f).distance - truth));
  }
  std::printf("largest error: plane fit %.3g, sphere fit %.3g (frame units)\n", planeError,
              sphereError);
  EXPECT_LT(sphereError, 0.25 * planeError);
}

TEST(SignedDistance, farCornersStayFiniteWhenWeightsUnderflow) {
  PointCloud plane = randomCloud(2000, 8);
  for (glm::dvec3& p : plane.positions) p.z = 0.0;
  plane.normals.assign(plane.size(), glm::vec3(0, 0, 1));
  const Evaluated e = withRadii(plane);
  const SdfEvaluator sdf(e.points, *e.tree, 1.0, FitMode::Sphere);
  // 0.4 frame units is thousands of σ: exp(-d²/2σ²) is 0 in double for every point.
  const CornerSample s = sdf.evaluate({0.5, 0.5, e.points.position[0].z + 0.4}, 0.0f);
  EXPECT_TRUE(std::isfinite(s.distance));
  EXPECT_NEAR(s.distance, 0.4, 1e-5);
}

TEST(SignedDistance, cornersBetweenOpposingSheetsSeeTheNearerSheet) {
  PointCloud sheets = randomCloud(20000, 9);
  const double gap = 0.004;
  for (size_t i = 0; i < sheets.size(); ++i) {
    const bool top = i % 2 == 0;
    sheets.positions[i].z = top ? gap / 2 : -gap / 2;
    sheets.normals.push_back(glm::vec3(0, 0, top ? 1.0f : -1.0f));
  }
  const Evaluated e = withRadii(sheets);
  const Frame frame = chooseFrame(sheets);
  ASSERT_GT(e.points.radius[0] * frame.size, gap);  // the sheets are closer than the radius
  const SdfEvaluator sdf(e.points, *e.tree, 1.0, FitMode::Sphere);
  const glm::dvec3 mid = toFrame(glm::dvec3(0.1, 0.2, 0.0), frame);
  for (double z : {0.3 * gap, -0.3 * gap, 0.9 * gap, -0.9 * gap}) {
    const double f =
        sdf.evaluate(mid + glm::dvec3(0, 0, z / frame.size), 0.0f).distance * frame.size;
    const double truth = std::abs(z) - gap / 2;  // negative between the sheets
    EXPECT_NEAR(f, truth, 0.05 * gap) << "z " << z;
  }
}

// Within a reach, the signed distance over any subset that holds every point within the reach of
// the corner is the one over all points; beyond it, nothing is given (what a chunk job's level of
// detail relies on).
TEST(SignedDistance, withinAReachASubsetHoldingItsPointsGivesWhatAllPointsGive) {
  const Evaluated e = withRadii(test::scanOf("sphere", 50000));
  const SdfEvaluator all(e.points, *e.tree, 1.0, FitMode::Sphere);
  std::mt19937_64 rng(11);
  std::uniform_int_distribution<size_t> pick(0, e.points.size() - 1);
  std::normal_distribution<double> g;
  size_t given = 0, refused = 0;
  for (int i = 0; i < 200; ++i) {
    const glm::dvec3 q =
        glm::dvec3(e.points.position[pick(rng)]) + glm::dvec3(g(rng), g(rng), g(rng)) * 0.003;
    const double reach = (i % 4 + 1) * 0.02;
    const float minSigma = float(i % 3) * 0.001f;
    std::vector<uint32_t> near;
    for (uint32_t k = 0; k < e.points.size(); ++k)
      if (glm::length(glm::dvec3(e.points.position[k]) - q) <= reach * 1.001) near.push_back(k);
    PointSet subset;
    PointSet::forEachColumn(
        [&](auto& to, const auto& from) {
          if (from.empty()) return;
          for (const uint32_t k : near) to.push_back(from[k]);
        },
        subset, e.points);
    const PointIndex index(subset.position);
    const SdfEvaluator part(subset, index, 1.0, FitMode::Sphere);
    const CornerSample whole = all.evaluate(q, minSigma);
    const std::optional<CornerSample> fromAll = all.evaluateWithin(q, minSigma, reach);
    const std::optional<CornerSample> fromPart = part.evaluateWithin(q, minSigma, reach);
    ASSERT_EQ(fromAll.has_value(), fromPart.has_value()) << i;
    if (!fromPart) {
      ++refused;
      continue;
    }
    ++given;
    EXPECT_EQ(fromAll->distance, whole.distance) << i;
    EXPECT_NEAR(fromPart->distance, whole.distance, 1e-7) << i;
    EXPECT_GT(glm::dot(fromPart->normal, whole.normal), 0.99999f) << i;
  }
  std::printf("%zu corners given within their reach, %zu refused\n", given, refused);
  EXPECT_GT(given, 50u);
  EXPECT_GT(refused, 10u);
}

TEST(Passive, boxDiskTestMatchesDenseSampling) {
  std::mt19937_64 rng(10);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  PointSet one;
  one.position = {glm::vec3(0.5f)};
  one.radius = {0.0f};
  one.normal = {glm::vec3(0.0f)};
  int touching = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const glm::vec3 n = glm::normalize(glm::vec3(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5));
    one.normal[0] = n;
    one.radius[0] = float(0.05 + 0.2 * u(rng));
    const glm::dvec3 lo(u(rng) * 0.6 + 0.2, u(rng) * 0.6 + 0.2, u(rng) * 0.6 + 0.2);
    const glm::dvec3 hi = lo + 0.1 + 0.1 * u(rng);
    // Dense samples of the disk.
    const glm::vec3 t1 = glm::normalize(
        glm::cross(n, std::abs(n.x) < 0.9f ? glm::vec3(1, 0, 0) : glm::vec3(0, 1, 0)));
    const glm::vec3 t2 = glm::cross(n, t1);
    bool sampled = false;
    for (int a = 0; a <= 200 && !sampled; ++a)
      for (int b = 0; b <= 200 && !sampled; ++b) {
        const float x = (a / 100.0f - 1.0f) * one.radius[0],
                    y = (b / 100.0f - 1.0f) * one.radius[0];
        if (x * x + y * y > one.radius[0] * one.radius[0]) continue;
        const glm::dvec3 p(one.position[0] + x * t1 + y * t2);
        sampled = glm::all(glm::greaterThanEqual(p, lo)) && glm::all(glm::lessThanEqual(p, hi));
      }
    const bool exact = diskTouchesBox(one, 0, lo, hi);
    if (sampled) {
      EXPECT_TRUE(exact) << "trial " << trial;  // sampling can only miss thin slivers
    }
    touching += exact;
  }
  EXPECT_GT(touching, 100);
}

// The octree of a generated scan with roughness, default options (fixed spacing and radius).
struct BuiltOctree {
  PointSet points;
  Octree octree;
};
BuiltOctree buildTestOctree(const std::string& shape, size_t n) {
  BuiltOctree b{withRadii(test::scanOf(shape, n)).points, {}};
  const PointIndex tree(b.points.position);
  estimateRoughness(b.points, findNeighbors(b.points, tree, 10));
  const SdfEvaluator sdf(b.points, tree, 1.0, FitMode::Sphere);
  CornerField corners;
  RadiusStats radii;
  radii.spacing = 1e-3;
  radii.medianRadius = 3e-3;
  b.octree = buildOctree(b.points, sdf, BuildOptions{}, radii, corners);
  return b;
}

TEST(Balance, touchingFilledLeavesDifferByAtMostOneLevel) {
  BuiltOctree built = buildTestOctree("cube", 40000);
  PointSet& points = built.points;
  Octree& octree = built.octree;
  markPassiveLeaves(octree, points);
  EXPECT_GT(balanceOctree(octree, points), 0u);
  std::vector<uint32_t> filled;
  for (uint32_t i = 0; i < octree.nodes.size(); ++i)
    if (octree.nodes[i].isFilled()) filled.push_back(i);
  const auto box = [&](const OctreeNode& n) {
    const auto c = mortonDecode(n.key);
    const double size = std::ldexp(1.0, -n.level);
    return std::pair(glm::dvec3(c[0], c[1], c[2]) * size,
                     glm::dvec3(c[0] + 1, c[1] + 1, c[2] + 1) * size);
  };
  size_t checked = 0;
  for (uint32_t a : filled) {  // brute force over pairs whose boxes touch
    const auto [alo, ahi] = box(octree.nodes[a]);
    for (uint32_t b : filled) {
      if (b <= a) continue;
      const auto [blo, bhi] = box(octree.nodes[b]);
      if (glm::any(glm::greaterThan(alo, bhi)) || glm::any(glm::greaterThan(blo, ahi))) continue;
      ++checked;
      EXPECT_LE(std::abs(int(octree.nodes[a].level) - int(octree.nodes[b].level)), 1);
    }
  }
  EXPECT_GT(checked, 1000u);
}

TEST(Chunks, everyNodeIsInExactlyOneChunkWithinTheBudget) {
  BuiltOctree built = buildTestOctree("torus", 60000);
  const Octree& octree = built.octree;
  const std::vector<ChunkPlan> plans = planChunks(octree, 500);
  std::vector<int> seen(octree.nodes.size(), 0);
  for (size_t p = 0; p < plans.size(); ++p) {
    EXPECT_LE(plans[p].nodes.size(), 500u);
    EXPECT_EQ(plans[p].parent == kNoParent, p == 0);
    if (p > 0) {
      EXPECT_LT(plans[plans[p].parent].cellLevel, plans[p].cellLevel);
    }
    for (uint32_t n : plans[p].nodes) ++seen[n];
    EXPECT_NO_THROW(layoutSurface(plans[p].topology, plans[p].cellLevel, plans[p].cellKey, 21));
  }
  for (size_t i = 0; i < octree.nodes.size(); ++i)
    EXPECT_EQ(seen[i], octree.nodes[i].kind == NodeKind::Empty ? 0 : 1);
  EXPECT_GT(plans.size(), 5u);
}

}  // namespace
}  // namespace iso
