// The neighbour index against brute force: k nearest, radius queries and all-points k-NN on
// uniform, clustered, duplicated, flat and unsorted points, inside and outside the unit cube.
#include <gtest/gtest.h>

#include <algorithm>
#include <glm/geometric.hpp>
#include <random>

#include "iso/check.h"
#include "pipeline/points/knn.h"

namespace iso {
namespace {

float distance2(const glm::vec3& a, const glm::vec3& b) {
  const glm::vec3 d = a - b;
  return glm::dot(d, d);
}

// The k smallest squared distances from q, by sorting all of them.
std::vector<float> bruteNearest(const std::vector<glm::vec3>& points, const glm::vec3& q, size_t k,
                                int64_t exclude = -1) {
  std::vector<float> d;
  for (size_t i = 0; i < points.size(); ++i)
    if (int64_t(i) != exclude) d.push_back(distance2(points[i], q));
  std::sort(d.begin(), d.end());
  d.resize(std::min(k, d.size()));
  return d;
}

enum class Layout { Uniform, Clustered, Duplicates, Flat, OutsideUnitCube };

std::vector<glm::vec3> makePoints(Layout layout, size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<glm::vec3> points(n);
  for (size_t i = 0; i < n; ++i) {
    glm::vec3 p(u(rng), u(rng), u(rng));
    switch (layout) {
      case Layout::Uniform:
        break;
      case Layout::Clustered:  // a dense ball 10^-4 across inside sparse points
        if (i % 2 == 0) p = glm::vec3(0.3f) + 1e-4f * p;
        break;
      case Layout::Duplicates:  // many points repeated exactly
        if (i % 3 != 0) p = points[i - i % 3];
        break;
      case Layout::Flat:
        p.z = 0.5f;
        break;
      case Layout::OutsideUnitCube:
        p = glm::vec3(5000.0f, -20.0f, 3.0f) + 100.0f * p;
        break;
    }
    points[i] = p;
  }
  return points;
}

class PointIndexTest : public ::testing::TestWithParam<Layout> {};

TEST_P(PointIndexTest, nearestMatchesBruteForce) {
  const std::vector<glm::vec3> points = makePoints(GetParam(), 3000, 7);
  const PointIndex index(points);
  ASSERT_EQ(index.size(), points.size());
  std::mt19937 rng(11);
  std::uniform_int_distribution<size_t> pick(0, points.size() - 1);
  std::normal_distribution<float> jitter(0.0f, 0.01f);
  for (const size_t k : {size_t{1}, size_t{4}, size_t{11}, size_t{40}}) {
    for (int trial = 0; trial < 200; ++trial) {
      glm::vec3 q = points[pick(rng)];
      if (trial % 2) q += glm::vec3(jitter(rng), jitter(rng), jitter(rng)) * glm::length(q + 1.0f);
      std::vector<uint32_t> found(k);
      std::vector<float> d2(k);
      ASSERT_EQ(index.nearest(q, k, found.data(), d2.data()), k);
      const std::vector<float> expected = bruteNearest(points, q, k);
      for (size_t j = 0; j < k; ++j) {
        EXPECT_EQ(d2[j], expected[j]) << "k " << k << " rank " << j;
        EXPECT_EQ(d2[j], distance2(points[found[j]], q));  // the index names the right point
      }
    }
  }
}

TEST_P(PointIndexTest, radiusQueryFindsExactlyThePointsWithin) {
  const std::vector<glm::vec3> points = makePoints(GetParam(), 3000, 8);
  const PointIndex index(points);
  std::mt19937 rng(12);
  std::uniform_int_distribution<size_t> pick(0, points.size() - 1);
  std::vector<std::pair<uint32_t, float>> found;
  for (int trial = 0; trial < 200; ++trial) {
    const glm::vec3 q = points[pick(rng)];
    // The radius of the 20th nearest: a neighbourhood of every density.
    const float radius = std::sqrt(bruteNearest(points, q, 20).back());
    index.withinRadius(q, radius, found);
    std::vector<uint32_t> got;
    for (const auto& [i, d2] : found) {
      got.push_back(i);
      EXPECT_EQ(d2, distance2(points[i], q));
    }
    std::vector<uint32_t> expected;
    for (uint32_t i = 0; i < points.size(); ++i)
      if (distance2(points[i], q) <= radius * radius) expected.push_back(i);
    std::sort(got.begin(), got.end());
    EXPECT_EQ(got, expected);
  }
}

TEST_P(PointIndexTest, allNearestMatchesBruteForce) {
  const std::vector<glm::vec3> points = makePoints(GetParam(), 2000, 9);
  const PointIndex index(points);
  std::vector<std::vector<float>> expected(points.size());
  for (size_t i = 0; i < points.size(); ++i)
    expected[i] = bruteNearest(points, points[i], 33, int64_t(i));
  for (const size_t k : {size_t{1}, size_t{10}, size_t{33}}) {
    std::vector<uint32_t> found(points.size() * k);
    std::vector<float> distance(points.size() * k);
    index.allNearest(k, found.data(), distance.data());
    for (size_t i = 0; i < points.size(); ++i) {
      for (size_t j = 0; j < k; ++j) {
        ASSERT_EQ(distance[i * k + j], std::sqrt(expected[i][j])) << "point " << i << " rank " << j;
        ASSERT_NE(found[i * k + j], i);  // never itself
        ASSERT_EQ(distance[i * k + j], std::sqrt(distance2(points[found[i * k + j]], points[i])));
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Layouts, PointIndexTest,
                         ::testing::Values(Layout::Uniform, Layout::Clustered, Layout::Duplicates,
                                           Layout::Flat, Layout::OutsideUnitCube));

TEST(PointIndex, tinyAndEmptySets) {
  const PointIndex empty(std::span<const glm::vec3>{});
  uint32_t i = 0;
  float d2 = 0.0f;
  EXPECT_EQ(empty.nearest(glm::vec3(0.0f), 3, &i, &d2), 0u);
  std::vector<std::pair<uint32_t, float>> found;
  empty.withinRadius(glm::vec3(0.0f), 1.0f, found);
  EXPECT_TRUE(found.empty());

  const std::vector<glm::vec3> two = {glm::vec3(0.1f), glm::vec3(0.2f)};
  const PointIndex index(two);
  std::array<uint32_t, 5> idx{};
  std::array<float, 5> dd{};
  EXPECT_EQ(index.nearest(glm::vec3(0.0f), 5, idx.data(), dd.data()), 2u);  // fewer than k
  EXPECT_EQ(idx[0], 0u);
  EXPECT_EQ(idx[1], 1u);
  std::array<uint32_t, 2> all{};
  std::array<float, 2> distance{};
  index.allNearest(1, all.data(), distance.data());
  EXPECT_EQ(all[0], 1u);
  EXPECT_EQ(all[1], 0u);
  EXPECT_THROW(index.allNearest(2, all.data(), distance.data()), InternalError);  // k < n
}

}  // namespace
}  // namespace iso
