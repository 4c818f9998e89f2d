// iso-bench-knn FILE [--k K] [--repeat N]: every point's k nearest neighbours (the radius of
// influence and the PCA normals, specs/pipeline.md §2–3), by iso's PointIndex and, beside it in
// the same run, by nanoflann (the k-d tree library DESIGN names) when it was found at build time.
// Prints seconds and points/s of each (index build and queries), their ratio, whether the two
// agree on every point's k-th distance, and the share of a 1M points/s conversion's time budget
// that the neighbour search alone takes. Positions are the conversion's (frame units, float, in
// Morton order).
#include <fmt/core.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "pipeline/io/readers.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

#ifdef ISO_BENCH_NANOFLANN
#include <nanoflann.hpp>
#endif

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Timing {
  double build = 0.0, query = 0.0;
  double total() const { return build + query; }
};

void printRow(const std::string& name, const Timing& t, size_t n) {
  fmt::print("  {:<28} {:>9.3f} {:>9.3f} {:>9.3f} {:>14.0f}\n", name, t.build, t.query, t.total(),
             double(n) / t.total());
}

#ifdef ISO_BENCH_NANOFLANN
struct Cloud {  // nanoflann's dataset adaptor over the same positions
  const std::vector<glm::vec3>& p;
  size_t kdtree_get_point_count() const { return p.size(); }
  float kdtree_get_pt(size_t i, size_t d) const { return p[i][int(d)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

// nanoflann's k nearest of every point (k + 1: a point finds itself first); the k-th distances.
Timing nanoflannNearest(const std::vector<glm::vec3>& points, size_t k, std::vector<float>& kth) {
  using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Cloud>,
                                                   Cloud, 3, uint32_t>;
  Timing t;
  const Cloud cloud{points};
  const auto start = Clock::now();
  Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  t.build = secondsSince(start);
  const auto queries = Clock::now();
  kth.resize(points.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      std::vector<uint32_t> index(k + 1);
                      std::vector<float> d2(k + 1);
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        const float q[3] = {points[i].x, points[i].y, points[i].z};
                        tree.knnSearch(q, k + 1, index.data(), d2.data());
                        kth[i] = std::sqrt(d2[k]);
                      }
                    });
  t.query = secondsSince(queries);
  return t;
}
#endif

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help") {
    fmt::print(stderr, "usage: iso-bench-knn FILE [--k K] [--repeat N]\n");
    return argc < 2 ? 2 : 0;
  }
  size_t k = 10;
  int repeat = 2;
  for (int a = 2; a + 1 < argc; a += 2) {
    const std::string option = argv[a];
    if (option == "--k")
      k = std::stoul(argv[a + 1]);
    else if (option == "--repeat")
      repeat = std::stoi(argv[a + 1]);
    else {
      fmt::print(stderr, "iso-bench-knn: unknown option {}\n", option);
      return 2;
    }
  }
  try {
    std::vector<glm::vec3> points;
    {
      const iso::PointCloud cloud = iso::readPointFile(argv[1]);
      const iso::PointSet set = iso::makePointSet(cloud, iso::chooseFrame(cloud));
      // In Morton order, as the conversion's stages see them (not timed).
      std::vector<uint32_t> order(set.size());
      for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
      std::sort(order.begin(), order.end(),
                [&](uint32_t a, uint32_t b) { return set.key[a] < set.key[b]; });
      points.reserve(order.size());
      for (const uint32_t i : order) points.push_back(set.position[i]);
    }
    const size_t n = points.size();
    if (n <= k) throw std::runtime_error("fewer points than k + 1");
    fmt::print("{}: {} points, k = {}, {} threads\n", argv[1], n, k,
               tbb::this_task_arena::max_concurrency());
    fmt::print("  {:<28} {:>9} {:>9} {:>9} {:>14}\n", "all k nearest", "build s", "query s",
               "total s", "points/s");
    for (int round = 0; round < repeat; ++round) {
      Timing own;
      std::vector<uint32_t> index(n * k);
      std::vector<float> distance(n * k);
      auto start = Clock::now();
      {
        const iso::PointIndex tree(points);
        own.build = secondsSince(start);
        start = Clock::now();
        tree.allNearest(k, index.data(), distance.data());
        own.query = secondsSince(start);
      }
      printRow("iso PointIndex::allNearest", own, n);
#ifdef ISO_BENCH_NANOFLANN
      std::vector<float> kth;
      const Timing other = nanoflannNearest(points, k, kth);
      printRow("nanoflann k-d tree", other, n);
      size_t agree = 0;
      for (size_t i = 0; i < n; ++i) agree += kth[i] == distance[i * k + k - 1];
      fmt::print("  ratio nanoflann / iso {:.2f}; k-th distances equal on {} of {} points\n",
                 other.total() / own.total(), agree, n);
#else
      fmt::print("  (nanoflann was not found at build time: no reference)\n");
#endif
      // 1M points/s end to end leaves n / 1e6 seconds for the whole conversion.
      fmt::print(
          "  at 1M points/s the whole conversion has {:.3f} s: the search alone takes {:.0f} %\n",
          double(n) / 1e6, 100.0 * own.total() / (double(n) / 1e6));
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "iso-bench-knn: {}\n", e.what());
    return 1;
  }
  return 0;
}
