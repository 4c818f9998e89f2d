// iso-bench-geom: speed of the shapes that accuracy tests measure against. Builds a bumpy icosphere
// mesh (20·4^subdivisions triangles; 8 gives 1.3M), then times the hierarchy build, closest-point
// queries near the surface (a scan's points with one spacing of noise, in scan order and in a
// spatially coherent order) and rays, on one thread and on all; then torus rays and generateScan.
//
// usage: iso-bench-geom [subdivisions=8] [scan points=10000000]
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <glm/geometric.hpp>
#include <vector>

#include "pipeline/geom/generate.h"
#include "pipeline/geom/random.h"
#include "pipeline/geom/shape.h"
#include "tests/geom/meshes.h"

namespace {

using Ray = std::pair<glm::dvec3, glm::dvec3>;

double secondsOf(const std::function<void()>& work) {
  const auto start = std::chrono::steady_clock::now();
  work();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

glm::dvec3 gaussian3(std::mt19937_64& rng) {
  return {iso::standardNormal(rng), iso::standardNormal(rng), iso::standardNormal(rng)};
}

// Morton order of the points in a 2^21 grid over their bounds.
void sortCoherently(std::vector<glm::dvec3>& points) {
  glm::dvec3 lower(1e300), upper(-1e300);
  for (const glm::dvec3& p : points) {
    lower = glm::min(lower, p);
    upper = glm::max(upper, p);
  }
  const auto key = [&](const glm::dvec3& p) {
    uint64_t k = 0;
    for (int bit = 20; bit >= 0; --bit)
      for (int axis = 0; axis < 3; ++axis) {
        const auto cell =
            uint64_t((p[axis] - lower[axis]) / (upper[axis] - lower[axis]) * 2097151.0);
        k = k << 1 | (cell >> bit & 1);
      }
    return k;
  };
  std::sort(points.begin(), points.end(),
            [&](const glm::dvec3& a, const glm::dvec3& b) { return key(a) < key(b); });
}

// Rays from a sphere around the shape towards points near its surface.
std::vector<Ray> raysAt(const iso::Shape& shape, size_t count, double radius) {
  std::mt19937_64 rng(11);
  std::vector<Ray> rays(count);
  for (auto& [origin, direction] : rays) {
    origin = radius * glm::normalize(gaussian3(rng));
    direction = shape.sample(rng).position + 0.05 * gaussian3(rng) - origin;
  }
  return rays;
}

double closestPerSecond(const iso::Shape& shape, const std::vector<glm::dvec3>& queries) {
  std::vector<double> distance(queries.size());
  const double seconds = secondsOf([&] {
    tbb::parallel_for(size_t(0), queries.size(),
                      [&](size_t i) { distance[i] = shape.closest(queries[i]).distance; });
  });
  return queries.size() / seconds;
}

double raysPerSecond(const iso::Shape& shape, const std::vector<Ray>& rays) {
  std::vector<char> hit(rays.size());
  const double seconds = secondsOf([&] {
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) {
      hit[i] = shape.intersect(rays[i].first, rays[i].second, 0.0, 10.0).has_value();
    });
  });
  return rays.size() / seconds;
}

void timeQueries(const iso::Shape& shape, const std::vector<glm::dvec3>& scanOrder,
                 const std::vector<glm::dvec3>& coherent, const std::vector<Ray>& rays,
                 int threads) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  std::printf(
      "  %d thread(s): closest %.0f/s in scan order, %.0f/s in coherent order; rays %.0f/s\n",
      threads, closestPerSecond(shape, scanOrder), closestPerSecond(shape, coherent),
      raysPerSecond(shape, rays));
}

}  // namespace

int main(int argc, char** argv) {
  const int subdivisions = argc > 1 ? std::atoi(argv[1]) : 8;
  const uint64_t scanPoints = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 10000000;
  const int allThreads = tbb::this_task_arena::max_concurrency();

  iso::TriangleMesh triangles = iso::test::bumpySphere(subdivisions, 0.1);
  const size_t triangleCount = triangles.triangles.size();
  std::unique_ptr<iso::Shape> mesh;
  const double buildSeconds = secondsOf([&] { mesh = iso::makeMeshShape(std::move(triangles)); });
  std::printf("mesh: %zu triangles, built in %.3f s on %d threads\n", triangleCount, buildSeconds,
              allThreads);
  const std::vector<glm::dvec3> queries =
      iso::generateScan(*mesh, {.count = 2000000, .noise = 1.0}).positions;
  std::vector<glm::dvec3> coherent = queries;
  sortCoherently(coherent);
  const std::vector<Ray> rays = raysAt(*mesh, 1000000, 3.0);
  timeQueries(*mesh, queries, coherent, rays, 1);
  timeQueries(*mesh, queries, coherent, rays, allThreads);

  const auto torus = iso::makeShape({.name = "torus"});
  std::printf("torus: rays %.0f/s on 1 thread\n", [&] {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    return raysPerSecond(*torus, raysAt(*torus, 1000000, 3.0));
  }());

  const auto sphere = iso::makeShape({});
  iso::PointCloud cloud;
  const double scanSeconds = secondsOf([&] {
    cloud = iso::generateScan(*sphere, {.count = scanPoints, .noise = 0.5, .densityRatio = 4.0});
  });
  std::printf("generateScan sphere: %zu points in %.3f s, %.0f points/s on %d threads\n",
              cloud.size(), scanSeconds, cloud.size() / scanSeconds, allThreads);
  return 0;
}
