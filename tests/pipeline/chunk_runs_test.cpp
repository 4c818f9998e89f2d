// Chunk runs of the octree stages (pipeline/convert/corner_stages.h): the plan checked against
// brute force, the merged tree checked for what one run guarantees (2:1 balance, patches that agree
// on shared faces, every filled leaf's corners sampled), and whole conversions as accurate as one
// run.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <memory>
#include <random>

#include "pipeline/base/options.h"
#include "pipeline/convert/corner_stages.h"
#include "pipeline/octree/cell_index.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

// Small chunks with halos of cells a quarter of an owned cell, as a 20M-point input has at the
// default settings (about 2M points a chunk, tested nodes at most 128 spacings wide).
BuildOptions chunked() {
  BuildOptions options;
  options.octreeChunkPoints = 8000;
  options.maxTestedEdge = 24.0;
  return options;
}

struct Prepared {
  PointSet points;
  std::unique_ptr<PointIndex> index;
  RadiusStats radii;
};

Prepared prepare(const PointCloud& cloud) {
  Prepared p;
  p.points = makePointSet(cloud, chooseFrame(cloud));
  sortByKey(p.points);
  mergeDuplicates(p.points);
  p.index = std::make_unique<PointIndex>(p.points.position);
  const Neighbors neighbors = findNeighbors(p.points, *p.index, 10);
  p.radii = estimateRadii(p.points, neighbors);
  estimateRoughness(p.points, neighbors);
  return p;
}

// A table cut by space numbers and finds keys as one table does, whatever parts are open when
// keys come (their own, another's, none) and however full their stretches get.
TEST(CellKeyIndex, numbersAndFindsKeysAsOneTableWhateverTheCut) {
  std::mt19937_64 random(7);
  constexpr uint32_t kGrid = 1u << kMaxLevel;
  std::vector<Key128> keys;
  for (int i = 0; i < 60000; ++i) {
    // Clustered grid points (a surface's are), on cell faces now and then, some repeated.
    const uint32_t cx = uint32_t(random() % 5) * (kGrid / 8), jitter = uint32_t(random() % 4096);
    const uint32_t x = std::min(kGrid, cx + jitter), y = uint32_t(random() % (kGrid + 1));
    const uint32_t z = i % 7 == 0 ? kGrid / 2 : uint32_t(random() % (kGrid + 1));
    keys.push_back({x | uint64_t(y) << 32, z | uint64_t(i % 3) << 32});
    if (i % 5 == 0) keys.push_back(keys[size_t(random() % keys.size())]);
  }
  const CellCut cut{3, {0, 40, 41, 200, 333}};
  KeyIndex<Key128> one(16);
  CellKeyIndex cutIndex(16);
  cutIndex.cutByCells(cut, 1000);
  size_t inStretches = 0;
  for (size_t i = 0; i < keys.size(); ++i) {
    if (i % 9000 == 0) cutIndex.openPart((i / 9000) % cut.firstCell.size(), 1500);  // 3,000 slots
    if (i == 50000) cutIndex.closeParts();
    const auto a = one.insert(keys[i]);
    const auto b = cutIndex.insert(keys[i]);
    ASSERT_EQ(a, b) << i;
    inStretches += b.second && i < 50000;
  }
  ASSERT_EQ(one.size(), cutIndex.size());
  for (size_t n = 0; n < one.size(); ++n) {
    ASSERT_EQ(cutIndex.find(one.key(uint32_t(n))), n);
    ASSERT_EQ(cutIndex.key(uint32_t(n)), one.key(uint32_t(n)));
  }
  EXPECT_EQ(cutIndex.find({12345, 1}), CellKeyIndex::kNone);
  EXPECT_GT(inStretches, 1000u);
}

TEST(ChunkRuns, thePlanCoversTheFrameWithMortonRangesOfAboutTheChunkPoints) {
  const Prepared p = prepare(test::scanOf("torus", 100000));
  const BuildOptions options = chunked();
  const OctreeChunkPlan plan = planOctreeChunks(p.points, p.radii, options);
  ASSERT_GE(plan.chunks(), 8u);
  // Chunks own cells four times as wide as the coarsest tested ones (no wider than maxTestedEdge
  // spacings, their parents wider), the halo's cells.
  const int tested = plan.haloLevel;
  EXPECT_EQ(plan.cellLevel + 2, tested);
  const double edge = std::ldexp(1.0, -tested) / p.radii.spacing;
  EXPECT_LE(edge, options.maxTestedEdge);
  EXPECT_GT(2.0 * edge, options.maxTestedEdge);
  EXPECT_EQ(plan.firstCell[0], 0u);
  ASSERT_EQ(plan.firstPoint.size(), plan.chunks() + 1);
  EXPECT_EQ(plan.firstPoint.back(), p.points.size());
  const int shift = 3 * (kMaxLevel - plan.cellLevel);
  for (size_t c = 0; c < plan.chunks(); ++c) {
    const uint64_t end =
        c + 1 < plan.chunks() ? plan.firstCell[c + 1] : uint64_t{1} << (3 * plan.cellLevel);
    ASSERT_LT(plan.firstCell[c], end);
    size_t cells = 0;
    uint64_t previous = ~uint64_t{0};
    for (uint32_t i = plan.firstPoint[c]; i < plan.firstPoint[c + 1]; ++i) {
      const uint64_t cell = p.points.key[i] >> shift;
      ASSERT_GE(cell, plan.firstCell[c]);
      ASSERT_LT(cell, end);
      cells += cell != previous;
      previous = cell;
    }
    // More points than asked for only in a chunk of one cell.
    const uint32_t points = plan.firstPoint[c + 1] - plan.firstPoint[c];
    EXPECT_TRUE(points <= options.octreeChunkPoints || cells == 1) << c;
  }
}

TEST(ChunkRuns, oneChunkWhenThePointsFitOrTheTreeIsTooShallow) {
  const Prepared p = prepare(test::scanOf("sphere", 20000));
  EXPECT_EQ(planOctreeChunks(p.points, p.radii, BuildOptions{}).chunks(), 1u);
  BuildOptions shallow = chunked();
  shallow.maxDepth = 2;  // shallower than the halo level
  EXPECT_EQ(planOctreeChunks(p.points, p.radii, shallow).chunks(), 1u);
}

// The filled leaves whose corners the field lacks, the pairs of touching filled leaves more than a
// level apart (by brute force over every leaf's 26 neighbours), and the largest disagreement of
// face-adjacent patches of different levels on their shared face (frame units).
struct TreeChecks {
  size_t unsampled = 0, unbalanced = 0, facePairs = 0;
  double worstFace = 0.0;
};

TreeChecks check(const CornerStageResults& r) {
  TreeChecks out;
  const Octree& tree = r.octree;
  const CornerField& field = r.closure.corners;
  const auto patchOf = [&](const OctreeNode& leaf) {
    Patch patch(leaf.level, leaf.key);
    for (int c = 0; c < kCorners; ++c)
      patch.distance[size_t(c)] =
          field.value[field.find(cornerPoint(leaf.level, leaf.key, c))].distance;
    return patch;
  };
  for (const OctreeNode& leaf : tree.nodes) {
    if (!leaf.isFilled()) continue;
    bool sampled = true;
    for (int c = 0; c < kCorners; ++c)
      sampled = sampled && field.find(cornerPoint(leaf.level, leaf.key, c)) != kNoNode;
    if (!sampled) {
      ++out.unsampled;
      continue;
    }
    const auto cell = mortonDecode(leaf.key);
    const int64_t cells = int64_t{1} << leaf.level;
    for (int d = 0; d < 27; ++d) {
      const std::array<int64_t, 3> n = {int64_t(cell[0]) + d % 3 - 1,
                                        int64_t(cell[1]) + (d / 3) % 3 - 1,
                                        int64_t(cell[2]) + d / 9 - 1};
      if (d == 13 || n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= cells || n[1] >= cells ||
          n[2] >= cells)
        continue;
      const OctreeNode& other = tree.nodes[tree.find(
          leaf.level, mortonEncode(uint32_t(n[0]), uint32_t(n[1]), uint32_t(n[2])))];
      if (!other.isFilled()) continue;
      if (other.level + 1 < leaf.level) ++out.unbalanced;
      const int changed = (d % 3 != 1) + ((d / 3) % 3 != 1) + (d / 9 != 1);
      if (changed != 1 || other.level + 1 != leaf.level) continue;
      // A face pair: compare the patches on a grid of the small leaf's face.
      const int axis = d % 3 != 1 ? 0 : ((d / 3) % 3 != 1 ? 1 : 2);
      const int side = (axis == 0 ? d % 3 : (axis == 1 ? (d / 3) % 3 : d / 9)) == 2;
      const Patch small = patchOf(leaf), large = patchOf(other);
      ++out.facePairs;
      for (int i = 0; i <= 4; ++i)
        for (int j = 0; j <= 4; ++j) {
          glm::dvec3 q = small.origin;
          q[axis] += side * small.size;
          q[(axis + 1) % 3] += small.size * i / 4.0;
          q[(axis + 2) % 3] += small.size * j / 4.0;
          out.worstFace = std::max(out.worstFace, std::abs(small.value(q) - large.value(q)));
        }
    }
  }
  return out;
}

// A shape scanned with noise, its points prepared and its octree stages run as chunk jobs and
// merged (small chunks: chunked()).
struct MergedRun {
  Prepared p;
  BuildOptions options = chunked();
  OctreeChunkPlan plan;
  std::unique_ptr<SdfEvaluator> sdf;
  ChunkRunStats stats;
  CornerStageResults merged;
};

std::unique_ptr<MergedRun> mergedRun(const char* shape) {
  auto run = std::make_unique<MergedRun>();
  run->p = prepare(test::scanOf(shape, 100000, true, 0.2));
  run->plan = planOctreeChunks(run->p.points, run->p.radii, run->options);
  run->sdf = std::make_unique<SdfEvaluator>(run->p.points, *run->p.index, run->options.smoothing,
                                            run->options.fit);
  CornerStageSeconds seconds;
  run->merged = runCornerStagesByChunk(run->p.points, run->plan, *run->sdf, run->options,
                                       run->p.radii, seconds, run->stats);
  return run;
}

TEST(ChunkRuns, theMergedTreeIsBalancedSampledAndCrackFreeAcrossSeams) {
  for (const char* shape : {"sphere", "cube", "torus"}) {
    const std::unique_ptr<MergedRun> run = mergedRun(shape);
    const PointSet& points = run->p.points;
    const OctreeChunkPlan& plan = run->plan;
    const ChunkRunStats& stats = run->stats;
    const CornerStageResults& merged = run->merged;
    ASSERT_GE(plan.chunks(), 8u) << shape;
    const TreeChecks c = check(merged);
    std::printf("%s: %zu chunks, halo %llu points, %zu seam splits, %zu face pairs, worst %.3g\n",
                shape, plan.chunks(), (unsigned long long)stats.haloPoints, stats.seamSplits,
                c.facePairs, c.worstFace);
    EXPECT_GT(stats.haloPoints, 0u) << shape;
    EXPECT_EQ(c.unsampled, 0u) << shape;
    EXPECT_EQ(c.unbalanced, 0u) << shape;
    EXPECT_GT(c.facePairs, 100u) << shape;
    EXPECT_LT(c.worstFace, 1e-6) << shape;  // float rounding of the snapped corners
    // Every point lies below exactly one node of the merged tree's leaves or empty cells.
    std::vector<uint32_t> covered(points.size(), 0);
    for (const OctreeNode& node : merged.octree.nodes)
      if (node.kind == NodeKind::Leaf)
        for (uint32_t i = node.pointBegin; i < node.pointEnd; ++i) ++covered[i];
    EXPECT_TRUE(std::all_of(covered.begin(), covered.end(), [](uint32_t n) { return n == 1; }))
        << shape;
  }
}

// The merge keeps the jobs' corner levels and hanging corners away from the seams and finds them
// again around the seams only: what a refresh over the whole merged tree gives, entry for entry,
// in the same order, with the same snapped values.
TEST(ChunkRuns, theMergesCornerLevelsAndHangingCornersAreTheWholeTreesRefresh) {
  for (const char* shape : {"sphere", "cube", "torus"}) {
    const std::unique_ptr<MergedRun> run = mergedRun(shape);
    const Closure& merged = run->merged.closure;
    Closure whole = merged;
    refreshCorners(run->merged.octree, whole);
    std::printf("%s: %zu seam splits, %zu seam fills, %zu hanging of %zu corners\n", shape,
                run->stats.seamSplits, run->stats.seamFills, merged.hanging.size(),
                merged.corners.size());
    ASSERT_GT(merged.hanging.size(), 1000u) << shape;
    test::expectSameClosure(merged, whole, shape);
  }
}

// The jobs' level-of-detail corners are what the whole run's evaluation over all points gives
// (up to the order of the sums), and they are most of the level of detail.
TEST(ChunkRuns, theJobsLevelOfDetailIsWhatAllPointsGive) {
  for (const char* shape : {"sphere", "torus"}) {
    const std::unique_ptr<MergedRun> run = mergedRun(shape);
    const PointSet& points = run->p.points;
    const BuildOptions& options = run->options;
    const OctreeChunkPlan& plan = run->plan;
    const SdfEvaluator& sdf = *run->sdf;
    const CornerStageResults& merged = run->merged;
    ASSERT_GE(plan.chunks(), 8u) << shape;
    const LodField all = sampleLodCorners(merged.octree, points, sdf, options, {}, plan.cut());
    const LodField jobs =
        sampleLodCorners(merged.octree, points, sdf, options, {}, plan.cut(), &merged.lod);
    ASSERT_EQ(all.value.size(), jobs.value.size()) << shape;
    // Every job sample of a corner in the tree: the value all points give at its level.
    size_t matched = 0;
    std::vector<uint8_t> fromJob(all.value.size(), 0);
    for (const LodSample& sample : merged.lod) {
      const uint32_t e = all.index.find(sample.key);
      if (e == CellKeyIndex::kNone) continue;
      ++matched;
      fromJob[e] = 1;
      EXPECT_NEAR(sample.value.distance, all.value[e].distance, 1e-6) << shape;
      EXPECT_GT(glm::dot(sample.value.normal, all.value[e].normal), 0.9999f) << shape;
    }
    EXPECT_EQ(jobs.fromSamples, size_t(std::count(fromJob.begin(), fromJob.end(), uint8_t{1})))
        << shape;
    // The jobs evaluate the corners of nodes finer than the halo's cells (this small tree has
    // few; a large scan's level of detail is nearly all of them).
    size_t fine = 0, covered = 0;
    for (uint32_t e = 0; e < all.value.size(); ++e)
      if (all.index.key(e).b >> 32 > plan.haloLevel) {
        ++fine;
        covered += fromJob[e];
      }
    std::printf(
        "%s: %zu level-of-detail corners, %zu finer than the halo's cells, %zu of them "
        "from the jobs (%zu samples)\n",
        shape, all.value.size(), fine, covered, merged.lod.size());
    EXPECT_GT(matched, 0u) << shape;
    EXPECT_GT(fine, 500u) << shape;
    EXPECT_GE(double(covered), 0.95 * double(fine)) << shape;
    // The field with the jobs' samples is the field without them.
    double worst = 0.0;
    for (uint32_t e = 0; e < all.value.size(); ++e)
      worst = std::max(worst, double(std::abs(all.value[e].distance - jobs.value[e].distance)));
    EXPECT_LT(worst, 1e-6) << shape;
  }
}

TEST(ChunkRuns, aChunkedConversionIsAsAccurateAsOneRun) {
  for (const char* shape : {"sphere", "torus", "cube"}) {
    const PointCloud cloud = test::scanOf(shape, 200000, false, 0.2);
    ShapeParams params;
    params.name = shape;
    test::TempDir dir;
    BuildOptions one = chunked();
    one.octreeChunkPoints = 1u << 30;
    const test::Converted a = test::convertAndLoad(cloud, dir / "one.iso", one);
    const test::Converted b = test::convertAndLoad(cloud, dir / "chunks.iso", chunked());
    ASSERT_FALSE(a.report.contains("octree_chunks"));
    ASSERT_GE(b.report["octree_chunks"]["chunks"].get<size_t>(), 8u);
    const nlohmann::json ea = test::evaluate(a, *makeShape(params));
    const nlohmann::json eb = test::evaluate(b, *makeShape(params));
    std::printf("%s: one run rms %.4f max %.4f holes %s; chunks rms %.4f max %.4f holes %s\n",
                shape, ea["rms_over_spacing"].get<double>(), ea["max_over_spacing"].get<double>(),
                ea["hole_rate"].dump().c_str(), eb["rms_over_spacing"].get<double>(),
                eb["max_over_spacing"].get<double>(), eb["hole_rate"].dump().c_str());
    EXPECT_LE(eb["rms_over_spacing"].get<double>(), 1.02 * ea["rms_over_spacing"].get<double>())
        << shape;
    EXPECT_LE(eb["max_over_spacing"].get<double>(), 1.02 * ea["max_over_spacing"].get<double>())
        << shape;
    EXPECT_LE(eb["hole_rate"].get<double>(), ea["hole_rate"].get<double>() + 1e-4) << shape;
    const double seenA = a.report["visibility"]["seen_through_fraction"].get<double>();
    const double seenB = b.report["visibility"]["seen_through_fraction"].get<double>();
    EXPECT_LE(seenB, seenA + 1e-4) << shape;
  }
}

TEST(ChunkRuns, oneThreadWritesTheSameBytesAsAll) {
  const PointCloud cloud = test::scanOf("torus", 100000, false, 0.2);
  test::TempDir dir;
  test::convertAndLoad(cloud, dir / "all.iso", chunked());
  {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    test::convertAndLoad(cloud, dir / "one.iso", chunked());
  }
  EXPECT_TRUE(test::readFile(dir / "all.iso") == test::readFile(dir / "one.iso"));
}

}  // namespace
}  // namespace iso
