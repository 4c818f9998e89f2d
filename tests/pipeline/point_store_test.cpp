// Points held for viewing (PointStore) against brute force: what is added comes back, thinning
// keeps every other point, a box reaching into the view is never culled, and a view's subsample
// keeps every point the view shows at a pixel's detail, fits its budget, and covers the pixels all
// the points cover where a uniform subsample of as many points does not.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <random>
#include <set>

#include "pipeline/points/point_store.h"

namespace iso {
namespace {

// A view from `eye` towards `target` (up: +y unless looking along it), 40° high, width × height.
PointView viewOf(const glm::dvec3& eye, const glm::dvec3& target, uint32_t width,
                 uint32_t height, glm::dvec3 up = {0, 1, 0}) {
  PointView v;
  v.eye = eye;
  v.forward = glm::normalize(target - eye);
  v.right = glm::normalize(glm::cross(v.forward, up));
  v.up = glm::cross(v.right, v.forward);
  v.tanHalfHeight = std::tan(glm::radians(20.0));
  v.aspect = double(width) / height;
  v.height = height;
  return v;
}

// The pixel a point projects to, or -1 outside the picture.
int64_t pixelOf(const PointView& v, const glm::dvec3& p) {
  const glm::dvec3 d = p - v.eye;
  const double z = glm::dot(d, v.forward);
  if (z <= 0) return -1;
  const double x = glm::dot(d, v.right) / (z * v.tanHalfHeight * v.aspect);
  const double y = glm::dot(d, v.up) / (z * v.tanHalfHeight);
  const uint32_t width = uint32_t(std::lround(v.aspect * v.height));
  const double px = (x + 1) * 0.5 * width, py = (1 - y) * 0.5 * v.height;
  if (px < 0 || py < 0 || px >= width || py >= v.height) return -1;
  return int64_t(py) * width + int64_t(px);
}

// The square [0, side]² of the plane z = 0, n × n points on a grid, in a random order (every
// k-th point of a grid's rows would take whole columns).
PointCloud plane(double side, int n) {
  PointCloud c;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) c.positions.push_back({side * x / (n - 1), side * y / (n - 1), 0});
  std::shuffle(c.positions.begin(), c.positions.end(), std::mt19937(11));
  return c;
}

std::set<int64_t> covered(const PointView& v, const std::vector<glm::dvec3>& points) {
  std::set<int64_t> pixels;
  for (const auto& p : points)
    if (const int64_t px = pixelOf(v, p); px >= 0) pixels.insert(px);
  return pixels;
}

TEST(PointStore, pointsComeBackAsTheyWereAddedAndThinningKeepsEveryOther) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PointCloud a, b;
  for (int i = 0; i < 1001; ++i) {
    a.positions.push_back(glm::dvec3(u(rng), u(rng), u(rng)) * 100.0 + 5000.0);
    a.colors.push_back(glm::vec3(float(u(rng) * 0.5 + 0.5), 0.25f, 1.0f));
    a.normals.push_back(glm::normalize(glm::vec3(u(rng), u(rng), 1.0)));
  }
  for (int i = 0; i < 500; ++i) b.positions.push_back(glm::dvec3(u(rng), u(rng), u(rng)));
  PointStore store;
  store.add(0, a);
  store.add(1, b);
  ASSERT_EQ(store.size(), 1501u);
  ASSERT_EQ(store.objects(), 2u);
  const auto all = store.every(1);
  ASSERT_EQ(all[0].size(), a.size());
  ASSERT_EQ(all[1].size(), b.size());
  EXPECT_FALSE(all[1].hasColors() || all[1].hasNormals());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_LT(glm::length(all[0].positions[i] - a.positions[i]), 1e-4);  // float, 10⁴ from 0
    EXPECT_LT(glm::length(all[0].colors[i] - a.colors[i]), 1e-4f);
    EXPECT_EQ(all[0].normals[i], a.normals[i]);
  }
  for (size_t i = 0; i < b.size(); ++i)
    EXPECT_LT(glm::length(all[1].positions[i] - b.positions[i]), 1e-3);
  // Every 3rd point counting across the objects: a's 0, 3, ..., 999, then b's from 1002 (its
  // point 1) on.
  const auto third = store.every(3);
  ASSERT_EQ(third[0].size(), 334u);
  ASSERT_EQ(third[1].size(), 167u);
  EXPECT_LT(glm::length(third[1].positions[0] - b.positions[1]), 1e-3);
  store.thin();
  const auto half = store.every(1);
  ASSERT_EQ(half[0].size(), 501u);
  ASSERT_EQ(half[1].size(), 250u);  // b's points 1001, 1003, ... are odd across the objects
  EXPECT_LT(glm::length(half[0].positions[500] - a.positions[1000]), 1e-4);
  EXPECT_LT(glm::length(half[1].positions[0] - b.positions[1]), 1e-3);
}

TEST(PointStore, aBoxThatReachesIntoTheViewIsNeverCulled) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0), s(0.01, 0.5);
  size_t seen = 0, culled = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const PointView v = viewOf({u(rng), u(rng), u(rng) + 2.0}, {u(rng), u(rng), u(rng)}, 160, 90);
    const glm::dvec3 lo(u(rng) * 2, u(rng) * 2, u(rng) * 2), hi = lo + glm::dvec3(s(rng), s(rng), s(rng));
    // Brute force: a grid of the box's points, any of which projects into the picture.
    bool inside = false;
    for (int i = 0; i <= 6 && !inside; ++i)
      for (int j = 0; j <= 6 && !inside; ++j)
        for (int k = 0; k <= 6 && !inside; ++k)
          inside = pixelOf(v, lo + (hi - lo) * glm::dvec3(i, j, k) / 6.0) >= 0;
    const bool sees = v.sees(lo, hi, 0.0);
    if (inside) {
      EXPECT_TRUE(sees) << trial;
    }
    seen += inside;
    culled += !sees;
  }
  EXPECT_GT(seen, 1000u);
  EXPECT_GT(culled, 5000u);  // the test culls at all
  // Behind the eye: culled.
  const PointView v = viewOf({0, 0, 5}, {0, 0, 0}, 100, 100);
  EXPECT_FALSE(v.sees({-1, -1, 6}, {1, 1, 7}));
  EXPECT_TRUE(v.sees({-1, -1, -1}, {1, 1, 1}));
}

TEST(PointStore, aCloseViewKeepsEveryPointItShowsWithinTheBudget) {
  PointStore store;
  store.add(0, plane(0.6, 600));  // spacing 0.001
  store.index();
  // From 0.1 above a corner: pixels a third as wide as the spacing, so every point shows.
  const PointView v = viewOf({0.1, 0.1, 0.1}, {0.1, 0.1, 0.0}, 256, 256, {0, 1, 0});
  const uint64_t budget = 30'000;  // of 360,000
  PointStore::Choice choice;
  const auto kept = store.forView(v, budget, &choice);
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_LE(kept[0].size(), budget);
  EXPECT_EQ(kept[0].size(), choice.kept);
  const auto all = store.every(1)[0];
  std::set<std::pair<double, double>> keptAt;
  for (const auto& p : kept[0].positions) keptAt.insert({p.x, p.y});
  size_t shown = 0, missing = 0;
  for (const auto& p : all.positions)
    if (pixelOf(v, p) >= 0) {
      ++shown;
      missing += !keptAt.count({p.x, p.y});
    }
  std::printf("close view: %zu points shown, %zu of them left out; %zu kept of %u\n", shown,
              missing, kept[0].size(), unsigned(budget));
  EXPECT_GT(shown, 4000u);
  EXPECT_EQ(missing, 0u);
  EXPECT_GE(choice.seen, shown);
}

TEST(PointStore, aGrazingViewCoversThePixelsAllThePointsCoverWithFewerPoints) {
  PointStore store;
  store.add(0, plane(0.6, 600));
  store.index();
  // Along the plane from before its near edge: near pixels hold a point each, far ones many.
  const PointView v = viewOf({0.3, -0.1, 0.15}, {0.3, 0.3, 0.0}, 128, 128, {0, 0, 1});
  const auto all = store.every(1)[0];
  const std::set<int64_t> full = covered(v, all.positions);
  size_t shown = 0;
  for (const auto& p : all.positions) shown += pixelOf(v, p) >= 0;
  // All that is asked for fits (the far points thinned to a pixel's detail), or a ninth of it.
  for (const auto& [budget, least] : {std::pair(uint64_t(360'000), 0.97), {40'000, 0.85}}) {
    PointStore::Choice choice;
    const auto kept = store.forView(v, budget, &choice)[0];
    EXPECT_LE(kept.size(), budget);
    const double coverage = double(covered(v, kept.positions).size()) / full.size();
    // A uniform subsample of as many points.
    const auto uniform = store.every(std::max<size_t>(all.size() / kept.size(), 1))[0];
    const double uniformCoverage = double(covered(v, uniform.positions).size()) / full.size();
    std::printf("budget %u: %zu kept (%zu in cells the view sees; %zu points shown), pixels "
                "covered %.4f (a uniform subsample of %zu: %.4f)\n",
                unsigned(budget), kept.size(), size_t(choice.seen), shown, coverage,
                uniform.size(), uniformCoverage);
    EXPECT_LT(kept.size(), shown * 3 / 4);
    EXPECT_GT(coverage, least);
    EXPECT_LT(uniformCoverage, coverage - 0.05);
  }
}

}  // namespace
}  // namespace iso
