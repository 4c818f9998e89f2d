// Kept points (`iso convert --keep-points`): the chunks' cells against brute force, every input
// point back within the stated precision (matched one to one, independently of the writer), colors
// and normals, far outliers, and the same bytes in and out of core.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <random>
#include <unordered_map>

#include "iso/reader.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "pipeline/base/options.h"
#include "pipeline/convert/convert.h"
#include "pipeline/io/color.h"
#include "pipeline/outofcore/spill.h"
#include "pipeline/output/keep_points.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"
#include "tests/pipeline/same_points.h"

namespace iso {
namespace {

using test::expectSamePoints;

PointCloud keptPointsOf(const Reader& reader) {
  PointCloud all;
  forEachKeptPoints(reader, [&](const PointCloud& points) {
    all.positions.insert(all.positions.end(), points.positions.begin(), points.positions.end());
    all.normals.insert(all.normals.end(), points.normals.begin(), points.normals.end());
    all.colors.insert(all.colors.end(), points.colors.begin(), points.colors.end());
  });
  return all;
}

// A scan with everything that makes cells hard: clusters, 300 copies of one point (more than a
// chunk), 8-bit colors, normals of any length (zero among them).
PointCloud hardCloud() {
  PointCloud cloud = test::scanOf("torus", 20000, true, 0.2, 5);
  std::mt19937 random(2);
  for (int i = 0; i < 300; ++i) {
    cloud.positions.push_back(cloud.positions[17]);
    cloud.normals.push_back(cloud.normals[17]);
  }
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (random() % 10 == 0) cloud.normals[i] *= 3.5f;
    if (random() % 40 == 0) cloud.normals[i] = glm::vec3(0.0f);
    cloud.colors.push_back(glm::vec3(srgb8ToLinear(uint8_t(random())),
                                     srgb8ToLinear(uint8_t(random())),
                                     srgb8ToLinear(uint8_t(i % 256))));
  }
  return cloud;
}

// A file of only the cloud's kept points, written straight (no conversion: no radii but the
// chunks' densities, the input's normals).
KeptPointsStats writeKeptPoints(const std::filesystem::path& path, const PointCloud& cloud,
                                const Frame& frame, int bits, uint32_t limit) {
  FileHeader header;
  header.frame = frame;
  header.maxLevel = kMaxLevel;
  Writer writer(path, header);
  const KeptPointsStats stats = keepPoints(writer, cloud, header, bits, limit);
  writer.finish();
  return stats;
}

TEST(KeptPoints, cellsAreTheCoarsestThatHoldAtMostTheLimitAndEveryPointComesBack) {
  const PointCloud cloud = hardCloud();
  const Frame frame = chooseFrame(cloud);
  test::TempDir dir;
  constexpr uint32_t kLimit = 250;
  constexpr int kBits = 20;
  const KeptPointsStats stats = writeKeptPoints(dir / "points.iso", cloud, frame, kBits, kLimit);
  EXPECT_EQ(stats.points, cloud.size());
  EXPECT_EQ(stats.coarserChunks, 0u);
  const Reader reader = Reader::open(dir / "points.iso");
  EXPECT_TRUE(verifyFile(reader).ok());
  ASSERT_EQ(reader.chunks().size(), stats.chunks + stats.subsampleChunks);
  EXPECT_GT(stats.chunks, cloud.size() / kLimit);
  const std::vector<bool> subsample = subsampleChunks(reader);

  // Brute force: the keys of all points, and for each cell how many points it holds.
  std::vector<uint64_t> keys;
  for (const glm::dvec3& p : cloud.positions) keys.push_back(keyOf(glm::vec3(toFrame(p, frame))));
  std::sort(keys.begin(), keys.end());
  const auto countIn = [&](uint8_t level, uint64_t cell) {
    const int shift = 3 * (kMaxLevel - level);
    return uint64_t(std::lower_bound(keys.begin(), keys.end(), (cell + 1) << shift) -
                    std::lower_bound(keys.begin(), keys.end(), cell << shift));
  };
  uint64_t previousEnd = 0;  // key range covered so far, at kMaxLevel
  size_t splitChunks = 0;
  for (const ChunkInfo& c : reader.chunks()) {
    if (subsample[c.id]) continue;
    const int shift = 3 * (kMaxLevel - c.level);
    const uint64_t begin = c.key << shift, end = (c.key + 1) << shift;
    EXPECT_LE(c.pointCount, kLimit);
    if (c.pointCount < countIn(c.level, c.key)) {  // only a finest cell is split over chunks
      EXPECT_EQ(c.level, kMaxLevel);
      ++splitChunks;
      EXPECT_GE(end, previousEnd);
    } else {
      EXPECT_EQ(c.pointCount, countIn(c.level, c.key));  // the whole cell
      EXPECT_GE(begin, previousEnd);                     // disjoint, in Morton order
    }
    // Coarsest: the parent cell holds more than the limit or reaches into earlier chunks.
    if (c.level > 0 && c.pointCount == countIn(c.level, c.key)) {
      const uint64_t parent = c.key >> 3;
      EXPECT_TRUE(countIn(uint8_t(c.level - 1), parent) > kLimit ||
                  (parent << (shift + 3)) < previousEnd)
          << "chunk " << c.id;
    }
    previousEnd = end;
    // Every point of the chunk lies in its cell (all are inside the frame here).
    const PointsChunk chunk = decodePointsChunk(reader, c.id);
    EXPECT_EQ(chunk.stepBits, kBits);
    for (const std::array<int32_t, 3>& o : chunk.offsets)
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(o[a], 0);
        EXPECT_LE(o[a], std::ldexp(1.0, kBits - c.level));
      }
  }
  EXPECT_EQ(splitChunks, 2u);  // 301 copies of one point in chunks of 250

  // Within half a step's diagonal of the input, one to one, with their colors and unit normals.
  const double bound = std::sqrt(3.0) / 2.0 * std::ldexp(frame.size, -kBits) * (1.0 + 1e-9);
  EXPECT_LE(stats.maxError, bound);
  EXPECT_GT(stats.maxError, bound / 4.0);  // the precision is the one asked for, not finer
  expectSamePoints(cloud, keptPointsOf(reader), bound);
}

// The subsample chunks over those of the test above: one tree whose every inner chunk has two or
// more children in its cell, whose subsamples hold at most the limit and only points of the scan,
// each a radius at least √8 times its finer copy's; every table entry's geometric error is the
// largest radius of its points.
TEST(KeptPoints, subsampleChunksFormATreeOfThinnedPointsOverTheChunks) {
  const PointCloud cloud = hardCloud();
  const Frame frame = chooseFrame(cloud);
  test::TempDir dir;
  constexpr uint32_t kLimit = 250;
  const KeptPointsStats stats = writeKeptPoints(dir / "points.iso", cloud, frame, 20, kLimit);
  const Reader reader = Reader::open(dir / "points.iso");
  const std::vector<bool> subsample = subsampleChunks(reader);
  std::vector<int> children(reader.chunks().size(), 0);
  size_t roots = 0;
  for (const ChunkInfo& c : reader.chunks()) {
    if (c.parent != kNoParent) {
      ++children[c.parent];
      EXPECT_TRUE(cellContains(reader.chunk(c.parent).level, reader.chunk(c.parent).key, c.level,
                               c.key));
    } else {
      ++roots;
    }
  }
  EXPECT_EQ(roots, 1u);
  EXPECT_GT(stats.subsampleChunks, stats.chunks / 8);
  // Every point of the scan, by its stored position (the same offsets in any chunk of a cell
  // level: compare frame positions to a step).
  std::map<std::array<int64_t, 3>, double> radiusAt;  // finest stored radius at a position
  const auto cellOf = [](const std::array<double, 3>& u) {
    return std::array<int64_t, 3>{std::llround(std::ldexp(u[0], 20)),
                                  std::llround(std::ldexp(u[1], 20)),
                                  std::llround(std::ldexp(u[2], 20))};
  };
  // Fine chunks first (they come before their subsamples in the file).
  for (const ChunkInfo& c : reader.chunks()) {
    const PointsChunk chunk = decodePointsChunk(reader, c.id);
    ASSERT_EQ(chunk.radii.size(), chunk.size());
    double largest = 0.0;
    for (size_t i = 0; i < chunk.size(); ++i) {
      const double r = decodePointRadius(chunk.radii[i]);
      EXPECT_GT(r, 0.0);
      largest = std::max(largest, r);
      const auto at = cellOf(pointFramePosition(c.level, c.key, chunk.stepBits, chunk.offsets[i]));
      if (!subsample[c.id]) {
        double& known = radiusAt[at];
        known = known == 0.0 ? r : std::min(known, r);
      } else {
        ASSERT_TRUE(radiusAt.contains(at)) << "chunk " << c.id << " point " << i;
        EXPECT_GE(r, std::sqrt(8.0) * radiusAt[at] * 0.999) << "chunk " << c.id;
      }
    }
    EXPECT_GE(double(c.geometricError), largest);
    EXPECT_LT(double(c.geometricError), largest * (1.0 + 1e-6));
    if (subsample[c.id]) {
      EXPECT_GE(children[c.id], 2);
      EXPECT_LE(c.pointCount, kLimit);
    }
  }
}

// A level of detail of the kept points under a budget: every chunk that is not a subsample is
// drawn exactly once (itself or through one ancestor), the points stay within the budget, no
// chunk of the cut could give way to its children within it, and the whole budget draws every
// kept point.
TEST(KeptPoints, aCutUnderABudgetCoversEveryChunkOnceWithinIt) {
  const PointCloud cloud = hardCloud();
  test::TempDir dir;
  writeKeptPoints(dir / "points.iso", cloud, chooseFrame(cloud), 20, 250);
  const Reader reader = Reader::open(dir / "points.iso");
  const std::vector<bool> subsample = subsampleChunks(reader);
  const auto& chunks = reader.chunks();
  const uint64_t rootPoints = [&] {
    uint64_t n = 0;
    for (const ChunkInfo& c : chunks) n += c.parent == kNoParent ? c.pointCount : 0;
    return n;
  }();
  for (const uint64_t budget : {uint64_t(1), rootPoints, uint64_t(cloud.size() / 4),
                                uint64_t(cloud.size() / 2), uint64_t(cloud.size())}) {
    const std::vector<uint32_t> cut = keptPointsCut(reader, budget);
    std::vector<bool> inCut(chunks.size(), false);
    uint64_t points = 0;
    for (uint32_t id : cut) {
      inCut[id] = true;
      points += chunks[id].pointCount;
    }
    for (const ChunkInfo& c : chunks) {
      if (subsample[c.id]) continue;
      int drawn = 0;  // c or an ancestor in the cut
      for (uint32_t a = c.id; a != kNoParent; a = chunks[a].parent) drawn += inCut[a];
      EXPECT_EQ(drawn, 1) << "budget " << budget << ", chunk " << c.id;
    }
    if (budget >= rootPoints) {
      EXPECT_LE(points, budget);
    }
    std::vector<uint64_t> childPoints(chunks.size(), 0);
    for (const ChunkInfo& c : chunks)
      if (c.parent != kNoParent) childPoints[c.parent] += c.pointCount;
    for (uint32_t id : cut) {
      if (childPoints[id] > 0) {
        EXPECT_GT(points - chunks[id].pointCount + childPoints[id], budget) << "chunk " << id;
      }
    }
    if (budget == cloud.size()) {
      EXPECT_EQ(points, cloud.size());
      // Decoded, they are the scan's points.
      uint64_t decoded = 0;
      for (uint32_t id : cut) decoded += decodeKeptPoints(reader, id).size();
      EXPECT_EQ(decoded, cloud.size());
    }
  }
}

TEST(KeptPoints, aFarOutlierGetsACoarserStepInItsOwnChunkOnly) {
  PointCloud cloud = test::scanOf("sphere", 5000, false, 0.0, 3);
  cloud.positions.push_back(glm::dvec3(1.0e4, -2.0, 1.0));  // removed as an outlier, still kept
  BuildOptions options;
  options.keepPoints = true;
  options.pointBits = 24;
  options.keptPointsPerChunk = 1000;
  test::TempDir dir;
  const nlohmann::json report = convertToIso(cloud, dir / "far.iso", options);
  EXPECT_EQ(report["points"]["outliers_removed"], 1);
  EXPECT_EQ(report["kept_points"]["points"], cloud.size());
  EXPECT_EQ(report["kept_points"]["coarser_chunks"], 1);
  const Reader reader = Reader::open(dir / "far.iso");
  EXPECT_TRUE(verifyFile(reader).ok());
  const double frameSize = reader.header().frame.size;
  int coarser = 0;
  for (const ChunkInfo& c : reader.chunks()) {
    if (c.kind != kPointsKind) continue;
    const PointsChunk chunk = decodePointsChunk(reader, c.id);
    if (chunk.stepBits < 24) {  // the outlier alone, last, in the root cell
      ++coarser;
      EXPECT_EQ(c.level, 0);
      EXPECT_EQ(c.pointCount, 1u);
      EXPECT_EQ(c.id, reader.chunks().size() - 1);
    }
  }
  EXPECT_EQ(coarser, 1);
  // The far point comes back within its chunk's step, the others within the one asked for.
  const PointCloud kept = keptPointsOf(reader);
  PointCloud near = cloud;
  near.positions.pop_back();
  size_t far = 0;
  for (size_t i = 0; i < kept.size(); ++i)
    if (kept.positions[i].x > 1e3) {
      far = i;
      EXPECT_LT(glm::length(kept.positions[i] - cloud.positions.back()), 1e-5);
    }
  PointCloud keptNear = kept;
  keptNear.positions.erase(keptNear.positions.begin() + ptrdiff_t(far));
  expectSamePoints(near, keptNear, std::sqrt(3.0) / 2.0 * std::ldexp(frameSize, -24) * 1.000001);
}

TEST(KeptPoints, outOfCoreWritesTheSameBytesAsInCore) {
  PointCloud cloud = hardCloud();
  cloud.positions.push_back(glm::dvec3(40.0, 3.0, -2.0));  // a far outlier: the frame changes
  cloud.normals.push_back(glm::vec3(0.0f, 0.0f, 1.0f));
  cloud.colors.push_back(glm::vec3(1.0f));
  BuildOptions options;
  options.orientBlockPoints = 256;
  options.keepPoints = true;
  options.keptPointsPerChunk = 300;
  test::TempDir dir;
  const nlohmann::json inCore = convertToIso(cloud, dir / "in.iso", options);
  SpillDirectory spill(dir.path());
  auto raw = std::make_unique<RawSpill>(spill, PointLayout{true, true, ""});
  raw->append(cloud);
  raw->finish();
  // Loads of 700 points: chunk cells of the points cross the loads' cells both ways.
  const nlohmann::json streamed =
      convertSpilled(*raw, spill, {700, 1, 4096}, dir / "out.iso", options);
  EXPECT_EQ(streamed["kept_points"], inCore["kept_points"]);
  EXPECT_GT(streamed["kept_points"]["chunks"].get<uint64_t>(), 60u);
  EXPECT_EQ(streamed["points"]["outliers_removed"], 1);
  EXPECT_TRUE(test::readFile(dir / "in.iso") == test::readFile(dir / "out.iso"));
  const Reader reader = Reader::open(dir / "out.iso");
  EXPECT_TRUE(verifyFile(reader).ok());
  expectSamePoints(cloud, keptPointsOf(reader),
                   std::sqrt(3.0) * std::ldexp(reader.header().frame.size, -24));
}

TEST(KeptPoints, aFileWithoutThemKeepsNone) {
  test::TempDir dir;
  convertToIso(test::scanOf("sphere", 3000, false), dir / "plain.iso", BuildOptions{});
  const Reader reader = Reader::open(dir / "plain.iso");
  EXPECT_EQ(keptPointsInfo(reader).chunks, 0u);
  for (const ChunkInfo& c : reader.chunks()) EXPECT_NE(c.kind, kPointsKind);
}

}  // namespace
}  // namespace iso
