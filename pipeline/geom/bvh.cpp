// Binned SAH build (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies", 2007):
// at each node the centroids are binned along every axis and the split between bins with the
// smallest surface area cost is taken; subtrees are built as parallel TBB tasks.
#include "pipeline/geom/bvh.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <glm/common.hpp>
#include <limits>
#include <numeric>
#include <optional>

namespace iso {
namespace {

constexpr int kBins = 16;
constexpr uint32_t kMaxLeafSize = 8;
// Cost of visiting a node relative to testing one primitive.
constexpr float kTraversalCost = 1.0f;
// Below this depth splits are by SAH; beyond it by the median, which halves the count and so bounds
// the depth by kMaxSahDepth + 32 < Bvh::kMaxDepth.
constexpr int kMaxSahDepth = 64;
constexpr uint32_t kParallelSize = 4096;
constexpr float kInfinity = std::numeric_limits<float>::infinity();

struct FloatBox {
  std::array<float, 3> lower{kInfinity, kInfinity, kInfinity};
  std::array<float, 3> upper{-kInfinity, -kInfinity, -kInfinity};

  void grow(const FloatBox& b) {
    for (int i = 0; i < 3; ++i) {
      lower[i] = std::min(lower[i], b.lower[i]);
      upper[i] = std::max(upper[i], b.upper[i]);
    }
  }
  void grow(const std::array<float, 3>& p) {
    for (int i = 0; i < 3; ++i) {
      lower[i] = std::min(lower[i], p[i]);
      upper[i] = std::max(upper[i], p[i]);
    }
  }
  // Half the surface area; empty boxes have none.
  float halfArea() const {
    if (lower[0] > upper[0]) return 0.0f;
    const float x = upper[0] - lower[0], y = upper[1] - lower[1], z = upper[2] - lower[2];
    return x * y + y * z + z * x;
  }
};

struct Primitive {
  FloatBox box;
  std::array<float, 3> centroid;
};

// Centroid bins along one axis.
struct Binning {
  int axis;
  float lower;
  float scale;  // bins per unit of length

  int operator()(const Primitive& p) const {
    return std::min(int((p.centroid[axis] - lower) * scale), kBins - 1);
  }
};

// None where the centroids do not spread along the axis (or too little for a finite scale).
std::optional<Binning> binningAlong(int axis, const FloatBox& centroids) {
  const float extent = centroids.upper[axis] - centroids.lower[axis];
  const float scale = float(kBins) / extent;
  if (!(extent > 0.0f) || !std::isfinite(scale)) return std::nullopt;
  return Binning{axis, centroids.lower[axis], scale};
}

struct Bin {
  FloatBox box;
  uint32_t count = 0;
};

struct Split {
  int axis = -1;  // -1: no split beats a leaf, or the centroids coincide
  int bin = 0;    // primitives in bins [0, bin] go left
  float cost = kInfinity;
};

// The float just below (above) x, so that the float box strictly contains the double one even
// after the rounding of x itself.
float roundDown(double x) { return std::nextafter(float(x), -kInfinity); }
float roundUp(double x) { return std::nextafter(float(x), kInfinity); }

class Builder {
 public:
  Builder(std::span<const Box> boxes, Bvh& bvh) : bvh_(bvh), primitives_(boxes.size()) {
    glm::dvec3 lower(std::numeric_limits<double>::infinity()), upper(-lower);
    for (const Box& b : boxes) {
      lower = glm::min(lower, b.lower);
      upper = glm::max(upper, b.upper);
    }
    bvh_.origin = 0.5 * (lower + upper);
    tbb::parallel_for(size_t(0), boxes.size(), [&](size_t i) { primitives_[i] = local(boxes[i]); });
    bvh_.order.resize(boxes.size());
    std::iota(bvh_.order.begin(), bvh_.order.end(), 0u);
    // The root takes pair 0 alone; every split takes one more pair, fewer than one per box.
    bvh_.pairs.resize(boxes.size() + 1);
  }

  void run() {
    build(0, 0, uint32_t(primitives_.size()), 0);
    bvh_.pairs.resize(pairCount_.load());
    bvh_.pairs.shrink_to_fit();
  }

 private:
  Primitive local(const Box& b) const {
    Primitive p;
    for (int i = 0; i < 3; ++i) {
      p.box.lower[i] = roundDown(b.lower[i] - bvh_.origin[i]);
      p.box.upper[i] = roundUp(b.upper[i] - bvh_.origin[i]);
      p.centroid[i] = 0.5f * (p.box.lower[i] + p.box.upper[i]);
    }
    return p;
  }

  const Primitive& primitive(uint32_t position) const { return primitives_[bvh_.order[position]]; }

  void build(uint32_t node, uint32_t begin, uint32_t end, int depth) {
    FloatBox box, centroids;
    for (uint32_t i = begin; i < end; ++i) {
      box.grow(primitive(i).box);
      centroids.grow(primitive(i).centroid);
    }
    BvhNode& n = bvh_.pairs[node >> 1].node[node & 1];
    std::copy(box.lower.begin(), box.lower.end(), n.lower);
    std::copy(box.upper.begin(), box.upper.end(), n.upper);
    const uint32_t middle = split(begin, end, box, centroids, depth);
    if (middle == begin) {
      n.first = begin;
      n.count = end - begin;
      return;
    }
    const uint32_t children = 2 * pairCount_.fetch_add(1);
    n.first = children;
    n.count = 0;
    auto left = [&] { build(children, begin, middle, depth + 1); };
    auto right = [&] { build(children + 1, middle, end, depth + 1); };
    if (end - begin >= kParallelSize) {
      tbb::parallel_invoke(left, right);
    } else {
      left();
      right();
    }
  }

  // Where to split [begin, end) after reordering it, or begin for a leaf.
  uint32_t split(uint32_t begin, uint32_t end, const FloatBox& box, const FloatBox& centroids,
                 int depth) {
    const uint32_t count = end - begin;
    if (count == 1) return begin;
    if (depth < kMaxSahDepth) {
      const Split s = bestSplit(begin, end, box, centroids);
      if (s.axis < 0 && count <= kMaxLeafSize) return begin;
      if (s.axis >= 0) {
        const Binning binOf = *binningAlong(s.axis, centroids);
        const uint32_t* middle =
            std::partition(bvh_.order.data() + begin, bvh_.order.data() + end,
                           [&](uint32_t p) { return binOf(primitives_[p]) <= s.bin; });
        return uint32_t(middle - bvh_.order.data());
      }
    }
    if (count <= kMaxLeafSize) return begin;
    return medianSplit(begin, end, centroids);
  }

  // The SAH cost of every split between bins on every axis where the centroids spread, relative to
  // a leaf (cost = primitive count). Every bin split leaves both sides non-empty.
  Split bestSplit(uint32_t begin, uint32_t end, const FloatBox& box,
                  const FloatBox& centroids) const {
    Split best;
    best.cost = float(end - begin);
    const float inverseArea = 1.0f / box.halfArea();
    for (int axis = 0; axis < 3; ++axis) {
      const std::optional<Binning> binOf = binningAlong(axis, centroids);
      if (!binOf) continue;
      std::array<Bin, kBins> bins;
      for (uint32_t i = begin; i < end; ++i) {
        Bin& bin = bins[(*binOf)(primitive(i))];
        bin.box.grow(primitive(i).box);
        ++bin.count;
      }
      considerBins(bins, axis, inverseArea, best);
    }
    return best;
  }

  static void considerBins(const std::array<Bin, kBins>& bins, int axis, float inverseArea,
                           Split& best) {
    std::array<float, kBins> rightCost;  // rightCost[i]: area × count of bins (i, kBins)
    FloatBox right;
    uint32_t rightCount = 0;
    for (int i = kBins - 1; i > 0; --i) {
      right.grow(bins[i].box);
      rightCount += bins[i].count;
      rightCost[i - 1] = right.halfArea() * float(rightCount);
    }
    const uint32_t total = rightCount + bins[0].count;
    FloatBox left;
    uint32_t leftCount = 0;
    for (int i = 0; i < kBins - 1; ++i) {
      left.grow(bins[i].box);
      leftCount += bins[i].count;
      if (leftCount == 0 || leftCount == total) continue;
      const float cost =
          kTraversalCost + (left.halfArea() * float(leftCount) + rightCost[i]) * inverseArea;
      if (cost < best.cost) best = {axis, i, cost};
    }
  }

  // Halve the range by the centroids' order along their widest axis.
  uint32_t medianSplit(uint32_t begin, uint32_t end, const FloatBox& centroids) {
    int axis = 0;
    for (int i = 1; i < 3; ++i)
      if (centroids.upper[i] - centroids.lower[i] > centroids.upper[axis] - centroids.lower[axis])
        axis = i;
    const uint32_t middle = begin + (end - begin) / 2;
    std::nth_element(bvh_.order.begin() + begin, bvh_.order.begin() + middle,
                     bvh_.order.begin() + end, [&](uint32_t a, uint32_t b) {
                       const float ca = primitives_[a].centroid[axis];
                       const float cb = primitives_[b].centroid[axis];
                       return ca < cb || (ca == cb && a < b);
                     });
    return middle;
  }

  Bvh& bvh_;
  std::vector<Primitive> primitives_;
  std::atomic<uint32_t> pairCount_{1};
};

}  // namespace

Bvh buildBvh(std::span<const Box> boxes) {
  Bvh bvh;
  if (boxes.empty()) return bvh;
  Builder builder(boxes, bvh);
  builder.run();
  return bvh;
}

}  // namespace iso
