// Crack-freeness (specs/pipeline.md §6): for every pair of face-adjacent filled leaves of different
// levels, the two trilinear patches agree on the shared face — to float rounding in the pipeline,
// and within one quantization step in the written file, where the ray caster's sign-change rule
// closes what is left (the accuracy tests count leaks of 10^5 rays).
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "pipeline/base/options.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

struct Built {
  PointSet points;
  std::unique_ptr<PointIndex> index;
  std::unique_ptr<SdfEvaluator> sdf;
  Octree tree;
  Closure closure;
  const CornerField& corners = closure.corners;
};

void buildStages(const PointCloud& cloud, Built& b) {
  const Frame frame = chooseFrame(cloud);
  b.points = makePointSet(cloud, frame);
  sortByKey(b.points);
  mergeDuplicates(b.points);
  b.index = std::make_unique<PointIndex>(b.points.position);
  const Neighbors neighbors = findNeighbors(b.points, *b.index, 10);
  const RadiusStats radii = estimateRadii(b.points, neighbors);
  estimateRoughness(b.points, neighbors);
  b.sdf = std::make_unique<SdfEvaluator>(b.points, *b.index, 1.0, FitMode::Sphere);
  CornerField corners;
  b.tree = buildOctree(b.points, *b.sdf, BuildOptions{}, radii, corners);
  markPassiveLeaves(b.tree, b.points);
  balanceOctree(b.tree, b.points);
  b.closure = sampleClosedSurface(b.tree, b.points, *b.sdf, std::move(corners));
}

// Two identical builds of a scan of the shape, one to change in the way under test and one in the
// way it is compared with.
void buildTwice(const char* shape, Built& a, Built& b) {
  const PointCloud scan = test::scanOf(shape, 60000);
  buildStages(scan, a);
  buildStages(scan, b);
}

// The patch of a filled leaf at frame point p.
double leafValue(const Built& b, const OctreeNode& leaf, const glm::dvec3& p) {
  Patch patch(leaf.level, leaf.key);
  for (int c = 0; c < kCorners; ++c)
    patch.distance[size_t(c)] =
        b.corners.value[b.corners.find(cornerPoint(leaf.level, leaf.key, c))].distance;
  return patch.value(p);
}

TEST(CrackFree, patchesOfAdjacentLeavesAgreeOnSharedFaces) {
  for (const char* shape : {"sphere", "cube"}) {
    Built b;
    buildStages(test::scanOf(shape, 100000), b);
    size_t pairs = 0;
    double worst = 0.0;
    for (const OctreeNode& leaf : b.tree.nodes) {
      if (!leaf.isFilled()) continue;
      const auto cell = mortonDecode(leaf.key);
      const double size = std::ldexp(1.0, -leaf.level);
      for (int face = 0; face < 6; ++face) {
        const int axis = face / 2, side = face % 2;
        std::array<int64_t, 3> n = {cell[0], cell[1], cell[2]};
        n[size_t(axis)] += side ? 1 : -1;
        if (n[size_t(axis)] < 0 || n[size_t(axis)] >= (int64_t{1} << leaf.level)) continue;
        const OctreeNode& other = b.tree.nodes[b.tree.find(
            leaf.level, mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])))];
        if (!other.isFilled() || other.level != leaf.level - 1) continue;
        ++pairs;
        for (int i = 0; i <= 4; ++i)
          for (int j = 0; j <= 4; ++j) {  // points of the small leaf's face
            glm::dvec3 p = glm::dvec3(cell[0], cell[1], cell[2]) * size;
            p[axis] += side ? size : 0.0;
            p[(axis + 1) % 3] += size * i / 4.0;
            p[(axis + 2) % 3] += size * j / 4.0;
            const double a = leafValue(b, leaf, p), c = leafValue(b, other, p);
            worst = std::max(worst, std::abs(a - c) / size);
          }
      }
    }
    std::printf("%s: %zu face pairs across levels, largest mismatch %.3g leaf edges\n", shape,
                pairs, worst);
    EXPECT_GT(pairs, 100u);
    EXPECT_LE(worst, 1e-5);  // float rounding of the corner values, relative to the leaf edge
  }
}

// Emptying leaves (as trimming does) and refreshing only the corners they touch gives what a
// refresh over the whole tree gives: the same corner levels, hanging corners in the same order
// with the same sources, and the same snapped values.
TEST(CrackFree, aRefreshAfterEmptyingLeavesIsTheWholeTreesRefresh) {
  for (const char* shape : {"sphere", "cube"}) {
    Built whole, touched;
    buildTwice(shape, whole, touched);
    // Every fifth filled leaf, of every level, with points or without.
    std::vector<uint32_t> emptied;
    size_t filled = 0;
    for (uint32_t i = 0; i < whole.tree.nodes.size(); ++i)
      if (whole.tree.nodes[i].isFilled() && filled++ % 5 == 0) emptied.push_back(i);
    const auto levelsBefore = std::vector<uint8_t>(whole.corners.coarsestLevel.begin(),
                                                   whole.corners.coarsestLevel.end());
    const size_t hangingBefore = whole.closure.hanging.size();
    for (Built* b : {&whole, &touched})
      for (const uint32_t i : emptied) b->tree.nodes[i].kind = NodeKind::Empty;
    refreshCorners(whole.tree, whole.closure);
    refreshCornersAround(touched.tree, touched.closure, emptied);

    test::expectSameClosure(touched.closure, whole.closure, shape);
    size_t levelsChanged = 0;
    for (size_t e = 0; e < whole.corners.size(); ++e)
      levelsChanged += whole.corners.coarsestLevel[e] != levelsBefore[e];
    std::printf("%s: %zu of %zu filled leaves emptied, %zu corner levels changed, %zu -> %zu "
                "hanging corners\n",
                shape, emptied.size(), filled, levelsChanged, hangingBefore,
                whole.closure.hanging.size());
    // The emptying changed what the refresh computes, so the comparison can fail.
    EXPECT_GT(levelsChanged, 100u);
    EXPECT_NE(hangingBefore, whole.closure.hanging.size());
  }
}

// Closing again after corners changed sign (as the corner fit makes some do) finds the filled
// leaves using those corners from the corners themselves and refreshes only around what the passes
// filled: the same tree and closure as the passes from every such leaf, found by looking at every
// filled leaf's corners, followed by a refresh over the whole tree.
TEST(CrackFree, closingAgainIsThePassesFromEveryChangedLeafAndAWholeRefresh) {
  for (const char* shape : {"sphere", "cube"}) {
    Built fast, brute;
    buildTwice(shape, fast, brute);
    std::vector<uint8_t> wasNegative(fast.corners.size());
    for (size_t e = 0; e < wasNegative.size(); ++e)
      wasNegative[e] = fast.corners.value[e].distance < 0.0f;
    // Every 40th corner in use moved across the surface, in both.
    size_t moved = 0;
    for (Built* b : {&fast, &brute})
      for (size_t e = 0, inUse = 0; e < b->corners.size(); ++e)
        if (b->corners.coarsestLevel[e] != kUnusedCorner && inUse++ % 40 == 0) {
          b->closure.corners.value[e].distance = -b->corners.value[e].distance;
          moved += b == &fast;
        }
    closeAgain(fast.tree, fast.points, *fast.sdf, fast.closure, wasNegative);
    std::vector<uint32_t> changed;
    for (uint32_t i = 0; i < brute.tree.nodes.size(); ++i) {
      const OctreeNode& leaf = brute.tree.nodes[i];
      if (!leaf.isFilled()) continue;
      for (int c = 0; c < kCorners; ++c) {
        const uint32_t e = brute.corners.find(cornerPoint(leaf.level, leaf.key, c));
        if (wasNegative[e] != uint8_t(brute.corners.value[e].distance < 0.0f)) {
          changed.push_back(i);
          break;
        }
      }
    }
    const size_t filledBefore = brute.closure.filled;
    closeFromLeaves(changed, brute.tree, brute.points, *brute.sdf, brute.closure);
    refreshCorners(brute.tree, brute.closure);
    std::printf("%s: %zu corners moved, %zu leaves using them, %zu cells filled again, %zu "
                "hanging corners\n",
                shape, moved, changed.size(), brute.closure.filled - filledBefore,
                brute.closure.hanging.size());
    EXPECT_GT(brute.closure.filled - filledBefore, 10u) << shape;  // the passes changed the tree
    EXPECT_EQ(fast.closure.refilled, brute.closure.filled - filledBefore) << shape;
    ASSERT_EQ(fast.tree.nodes.size(), brute.tree.nodes.size()) << shape;
    for (size_t i = 0; i < fast.tree.nodes.size(); ++i)
      ASSERT_EQ(fast.tree.nodes[i].kind, brute.tree.nodes[i].kind) << shape << " node " << i;
    test::expectSameClosure(fast.closure, brute.closure, shape);
  }
}

TEST(CrackFree, writtenPatchesAgreeWithinAQuantizationStep) {
  test::TempDir dir;
  const test::Converted c =
      test::convertAndLoad(test::scanOf("sphere", 100000), dir / "sphere.iso");
  const SurfaceModel& s = c.surface;
  size_t pairs = 0, exact = 0;
  double worstSteps = 0.0;
  for (uint32_t id = 0; id < s.leaves().size(); ++id) {
    const auto& leaf = s.leaves()[id];
    const auto cell = mortonDecode(leaf.key);
    const double size = std::ldexp(1.0, -leaf.level);
    for (int face = 0; face < 6; ++face) {
      const int axis = face / 2, side = face % 2;
      glm::dvec3 probe = (glm::dvec3(cell[0], cell[1], cell[2]) + 0.5) * size;
      probe[axis] += side ? 0.75 * size : -0.75 * size;
      const uint32_t other = s.findLeaf({probe.x, probe.y, probe.z});
      if (other == kNoNode || s.leaves()[other].level != leaf.level - 1) continue;
      ++pairs;
      const double step = nodeDiagonal(uint8_t(leaf.level - 1)) / 127.0;  // the coarser leaf's step
      double mismatch = 0.0;
      for (int i = 0; i <= 4; ++i)
        for (int j = 0; j <= 4; ++j) {
          glm::dvec3 p = glm::dvec3(cell[0], cell[1], cell[2]) * size;
          p[axis] += side ? size : 0.0;
          p[(axis + 1) % 3] += size * i / 4.0;
          p[(axis + 2) % 3] += size * j / 4.0;
          mismatch = std::max(mismatch, std::abs(s.evaluate(id, {p.x, p.y, p.z}).distance -
                                                 s.evaluate(other, {p.x, p.y, p.z}).distance));
        }
      exact += mismatch <= 1e-7 * size ? 1 : 0;
      worstSteps = std::max(worstSteps, mismatch / step);
    }
  }
  std::printf("%zu face pairs across levels in the file, %zu exact, largest mismatch %.3f steps\n",
              pairs, exact, worstSteps);
  EXPECT_GT(pairs, 100u);
  EXPECT_LE(worstSteps, 1.0);
}

}  // namespace
}  // namespace iso
