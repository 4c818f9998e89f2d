// Stray points (specs/pipeline.md, "Stray points"): single returns, small groups and sparse dust
// at several distances from a scanned sphere are removed and counted, the sphere comes out as
// accurate as when converted alone, and no filled leaf is left near a removed point.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <numeric>
#include <random>

#include "pipeline/io/readers.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

constexpr double kRadius = 1.0;

struct StrayCase {
  const char* name;
  std::vector<glm::dvec3> strays;
};

glm::dvec3 direction(std::mt19937& random) {
  std::normal_distribution<double> n;
  for (;;) {
    const glm::dvec3 d(n(random), n(random), n(random));
    if (glm::length(d) > 1e-3) return glm::normalize(d);
  }
}

// Single returns at distances from 0.3 to 500 from the surface, and one at the centre.
StrayCase singles(std::mt19937& random) {
  StrayCase c{"single points", {glm::dvec3(0.0)}};
  for (const double d : {0.3, 0.6, 2.0, 20.0, 500.0})
    c.strays.push_back(direction(random) * (kRadius + d));
  return c;
}

// Tight groups (a bird, multipath) of 3 to 40 points, 0.4 to 5 from the surface, one inside.
StrayCase groups(std::mt19937& random) {
  StrayCase c{"small groups", {}};
  std::normal_distribution<double> spread(0.0, 0.01);
  const int counts[] = {3, 8, 20, 40};
  const double distances[] = {0.4, 1.5, 5.0, -0.6};
  for (int g = 0; g < 4; ++g) {
    const glm::dvec3 centre = direction(random) * (kRadius + distances[g]);
    for (int i = 0; i < counts[g]; ++i)
      c.strays.push_back(centre + glm::dvec3(spread(random), spread(random), spread(random)));
  }
  return c;
}

// Sparse dust in a box around the sphere, none within 0.25 of its surface.
StrayCase dust(std::mt19937& random) {
  StrayCase c{"dust", {}};
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  while (c.strays.size() < 300) {
    const glm::dvec3 p(u(random), u(random), u(random));
    if (std::abs(glm::length(p) - kRadius) > 0.25) c.strays.push_back(p);
  }
  return c;
}

PointCloud withStrays(const PointCloud& object, const std::vector<glm::dvec3>& strays) {
  PointCloud cloud = object;
  for (const glm::dvec3& p : strays) {
    cloud.positions.push_back(p);
    cloud.normals.push_back(glm::vec3(0.0f));  // estimated, as for points without normals
  }
  return cloud;
}

// The distance from p (frame units) to the box of a leaf.
double distanceToLeaf(const Vec3& p, const SurfaceModel::Leaf& leaf) {
  const double size = std::ldexp(1.0, -int(leaf.level));
  const std::array<uint32_t, 3> cell = mortonDecode(leaf.key);
  double sum = 0.0;
  for (int a = 0; a < 3; ++a) {
    const double lo = cell[a] * size, hi = lo + size;
    const double d = std::max({lo - p[a], 0.0, p[a] - hi});
    sum += d * d;
  }
  return std::sqrt(sum);
}

// The distance (world units) from a point to the nearest filled leaf of a converted file.
double nearestLeaf(const test::Converted& c, const glm::dvec3& world) {
  const Frame frame = c.surface.header().frame;
  const Vec3 p{(world.x - frame.origin[0]) / frame.size, (world.y - frame.origin[1]) / frame.size,
               (world.z - frame.origin[2]) / frame.size};
  double nearest = std::numeric_limits<double>::max();
  for (const SurfaceModel::Leaf& leaf : c.surface.leaves())
    nearest = std::min(nearest, distanceToLeaf(p, leaf) * frame.size);
  return nearest;
}

TEST(Strays, areRemovedCountedAndLeaveTheObjectAsAccurateAsAlone) {
  const PointCloud object = test::scanOf("sphere", 40000, true, 0.2, 3);
  const auto truth = makeShape(ShapeParams{.name = "sphere"});
  test::TempDir dir;
  const test::Converted alone = test::convertAndLoad(object, dir / "alone.iso");
  const double aloneRms = test::evaluate(alone, *truth)["rms"].get<double>();
  const double spacing = alone.report["spacing"].get<double>();
  EXPECT_EQ(alone.report["points"]["outliers_removed"], 0);

  std::mt19937 random(17);
  for (const StrayCase& c : {singles(random), groups(random), dust(random)}) {
    SCOPED_TRACE(c.name);
    const test::Converted with = test::convertAndLoad(withStrays(object, c.strays), dir / "s.iso");
    EXPECT_EQ(with.report["points"]["outliers_removed"].get<size_t>(), c.strays.size());
    EXPECT_DOUBLE_EQ(with.report["spacing"].get<double>(), spacing);  // no statistic moves
    const double rms = test::evaluate(with, *truth)["rms"].get<double>();
    std::printf("%s: %zu strays, rms %.3g (alone %.3g)\n", c.name, c.strays.size(), rms, aloneRms);
    EXPECT_LE(std::abs(rms - aloneRms), 0.10 * aloneRms);
    // No filled leaf within 2 spacings of a removed point (brute force over all leaves).
    double nearest = std::numeric_limits<double>::max();
    for (const glm::dvec3& p : c.strays) nearest = std::min(nearest, nearestLeaf(with, p));
    EXPECT_GT(nearest, 2.0 * spacing)
        << "a filled leaf " << nearest / spacing << " spacings from a removed point";
  }
}

TEST(Strays, keepOutliersKeepsThemAndAFarGroupThenMakesASurface) {
  std::mt19937 random(5);
  const std::vector<glm::dvec3> strays = groups(random).strays;
  const PointCloud cloud = withStrays(test::scanOf("sphere", 20000, true, 0.2, 4), strays);
  BuildOptions keep;
  keep.removeOutliers = false;
  test::TempDir dir;
  const test::Converted kept = test::convertAndLoad(cloud, dir / "kept.iso", keep);
  EXPECT_EQ(kept.report["points"]["outliers_removed"], 0);
  const test::Converted removed = test::convertAndLoad(cloud, dir / "removed.iso");
  EXPECT_EQ(removed.report["points"]["outliers_removed"], strays.size());
  // The group of 20, 5 from the surface, makes a surface when kept, none when removed.
  EXPECT_LT(nearestLeaf(kept, strays[11]), 0.05);
  EXPECT_GT(nearestLeaf(removed, strays[11]), 3.0);
}

TEST(Strays, groupsAndThresholdsAgainstBruteForce) {
  // A dense square, a small cluster beside it, a lone point above it and a large sparse cloud
  // far from it: the union-find's groups are the connected components of the near edges, and a
  // group is a stray when small or when its median k-th distance passes the threshold, by brute
  // force.
  PointCloud cloud;
  std::mt19937 random(9);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int i = 0; i < 3000; ++i) cloud.positions.push_back({u(random), u(random), 0.0});
  for (int i = 0; i < 30; ++i)
    cloud.positions.push_back({5 + 0.05 * u(random), 0.05 * u(random), 0});
  cloud.positions.push_back({0.5, 0.5, 0.5});  // above the square, alone
  for (int i = 0; i < 200; ++i)  // a sparse cloud: about 70 times the square's k-th distance
    cloud.positions.push_back({20 + 20 * u(random), 20 * u(random), 20 * u(random)});
  const Frame frame = chooseFrame(cloud);
  PointSet points = makePointSet(cloud, frame);
  const PointIndex index(points.position);
  const Neighbors neighbors = findNeighbors(points, index, 10);
  const Strays strays = findStrays(points.size(), neighbors, 64);
  const size_t k = 10, n = points.size();
  // Brute force: components by repeated relaxation over the same edges.
  std::vector<uint32_t> label(n);
  std::iota(label.begin(), label.end(), 0u);
  for (bool changed = true; changed;) {
    changed = false;
    for (size_t i = 0; i < n; ++i)
      for (size_t e = 0; e < k; ++e) {
        const uint32_t j = neighbors.index[i * k + e];
        const float reach =
            3.0f * std::min(neighbors.distance[i * k + k - 1], neighbors.distance[j * k + k - 1]);
        if (neighbors.distance[i * k + e] > reach) continue;
        const uint32_t m = std::min(label[i], label[j]);
        if (label[i] != m || label[j] != m) changed = true;
        label[i] = label[j] = m;
      }
  }
  std::vector<float> kth(n);
  for (size_t i = 0; i < n; ++i) kth[i] = neighbors.distance[i * k + k - 1];
  const float threshold = sparseThreshold(kth);
  size_t small = 0, sparse = 0;
  for (size_t i = 0; i < n; ++i) {
    std::vector<float> group;
    for (size_t j = 0; j < n; ++j)
      if (label[j] == label[i]) group.push_back(kth[j]);
    std::sort(group.begin(), group.end());
    const bool isSmall = group.size() < 64 && 2 * group.size() < n;
    const bool isSparse = !isSmall && 2 * group.size() < n && group[group.size() / 2] > threshold;
    small += isSmall;
    sparse += isSparse;
    EXPECT_EQ(bool(strays.flagged[i]), isSmall || isSparse) << "source " << points.source[i];
    EXPECT_EQ(bool(strays.flagged[i]), points.source[i] >= 3000) << "source " << points.source[i];
  }
  EXPECT_EQ(strays.grouped, small);
  EXPECT_EQ(strays.sparse, sparse);
  EXPECT_EQ(small, 31u);
  EXPECT_GE(sparse, 150u);  // most of the cloud; its loosest points may form small groups

  // The sparse threshold: the median k-th distance times max(32, e^(8σ)), σ = 1.4826 MAD(log).
  for (const float spread : {0.1f, 1.0f}) {
    std::vector<float> kth(1000, 2.0f);  // logs: ln 2 ± spread on a quarter each
    for (size_t i = 0; i < 250; ++i) {
      kth[i] = 2.0f * std::exp(-spread);
      kth[999 - i] = 2.0f * std::exp(spread);
    }
    const double factor = std::max(32.0, std::exp(8.0 * 1.4826 * spread));
    EXPECT_NEAR(sparseThreshold(kth) / (2.0 * factor), 1.0, 1e-4) << spread;
  }
}

TEST(Strays, theSparseEndOfASmoothlyVaryingDensityIsKept) {
  // Density falls 10^4-fold along x on a sphere: the sparse end's k-th distances are up to 100
  // times the median, but the group is one (neighbours' distances change little from point to
  // point), so nothing is a stray.
  const auto truth = makeShape(ShapeParams{.name = "sphere"});
  GenerateOptions g;
  g.count = 30000;
  g.densityRatio = 1e4;
  const PointCloud cloud = generateScan(*truth, g);
  const Frame frame = chooseFrame(cloud);
  PointSet points = makePointSet(cloud, frame);
  sortByKey(points);
  const PointIndex index(points.position);
  const Neighbors neighbors = findNeighbors(points, index, 10);
  std::vector<float> kth(points.size());
  for (size_t i = 0; i < points.size(); ++i) kth[i] = neighbors.distance[i * 10 + 9];
  std::sort(kth.begin(), kth.end());
  EXPECT_GT(kth.back(), sparseThreshold(kth));  // a rule per point would remove the sparse end
  const Strays strays = findStrays(points.size(), neighbors, 64);
  EXPECT_EQ(strays.sparse + strays.grouped, 0u);
}

TEST(Strays, aRealScanWithStraysKeepsItsAccuracy) {
  // The bunny with birds, dust and single returns around it: its points' distances to the zero
  // set (the report's accuracy, in world units) stay within 10 % of the bunny converted alone.
  const std::filesystem::path file =
      std::filesystem::path(ISO_SHARED_DATA_DIR) / "bunny_zipper.ply";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << "no " << file;
  PointCloud bunny = readPointFile(file);
  test::TempDir dir;
  const test::Converted alone = test::convertAndLoad(bunny, dir / "alone.iso");
  std::mt19937 random(3);
  std::normal_distribution<double> spread(0.0, 0.0005);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  const glm::dvec3 centre(-0.017, 0.11, 0.0);  // about the bunny's middle
  PointCloud with = bunny;
  for (int g = 0; g < 6; ++g) {  // birds 0.1 to 0.6 above it
    const glm::dvec3 at = centre + glm::dvec3(u(random), 0.2 + 0.1 * g, u(random));
    for (int i = 0; i < 5 + 7 * g; ++i)
      with.positions.push_back(at + glm::dvec3(spread(random), spread(random), spread(random)));
  }
  for (const double d : {1.0, 10.0, 100.0})  // single returns metres away
    with.positions.push_back(centre + glm::dvec3(d, d, -d));
  const size_t added = with.size() - bunny.size();
  const test::Converted converted = test::convertAndLoad(with, dir / "with.iso");
  EXPECT_EQ(converted.report["points"]["outliers_removed"].get<size_t>(), added);
  EXPECT_DOUBLE_EQ(converted.report["spacing"].get<double>(),
                   alone.report["spacing"].get<double>());
  const double rms = converted.report["accuracy"]["rms"].get<double>();
  const double aloneRms = alone.report["accuracy"]["rms"].get<double>();
  EXPECT_LE(std::abs(rms - aloneRms), 0.10 * aloneRms) << rms << " vs " << aloneRms;
}

}  // namespace
}  // namespace iso
