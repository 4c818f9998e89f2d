// The out-of-core conversion: the distribution of points into chunks checked against brute force,
// and whole conversions with hundreds of chunks that must write the same bytes as in core.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <glm/geometric.hpp>
#include <map>
#include <random>
#include <set>

#include "iso/reader.h"
#include "pipeline/base/options.h"
#include "pipeline/base/progress.h"
#include "pipeline/convert/convert.h"
#include "pipeline/outofcore/outofcore.h"
#include "pipeline/outofcore/spill.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

std::unique_ptr<RawSpill> spillOf(SpillDirectory& directory, const PointCloud& cloud) {
  auto raw =
      std::make_unique<RawSpill>(directory, PointLayout{cloud.hasNormals(), cloud.hasColors(), ""});
  raw->append(cloud);
  raw->finish();
  return raw;
}

TEST(Distribution, putsEveryPointInTheChunkWhoseCellHoldsItAndLoadsBoxesExactly) {
  const PointCloud cloud = test::scanOf("torus", 30000, true, 0.3);
  test::TempDir dir;
  SpillDirectory spill(dir.path());
  const auto raw = spillOf(spill, cloud);
  const Frame frame = chooseFrame(cloud);
  const Distribution distribution(spill, *raw, frame, 700);
  ASSERT_GT(distribution.chunks().size(), 40u);

  std::vector<int> seen(cloud.size(), 0);
  uint64_t previousEnd = 0;
  for (const SpillChunk& chunk : distribution.chunks()) {
    EXPECT_EQ(chunk.begin, previousEnd);  // contiguous, in Morton order
    previousEnd = chunk.end;
    EXPECT_TRUE(chunk.size() <= 700 || chunk.level == Distribution::kFineLevel);
    const LoadedPoints loaded = distribution.load(chunk);
    ASSERT_EQ(loaded.source.size(), chunk.size());
    for (size_t i = 0; i < loaded.source.size(); ++i) {
      const uint32_t s = loaded.source[i];
      ++seen[s];
      EXPECT_EQ(loaded.cloud.positions[i], cloud.positions[s]);
      EXPECT_EQ(loaded.cloud.normals[i], cloud.normals[s]);
      const uint64_t key = keyOf(glm::vec3(toFrame(cloud.positions[s], frame)));
      EXPECT_EQ(key >> (3 * (kMaxLevel - chunk.level)), chunk.key);
    }
  }
  EXPECT_EQ(previousEnd, cloud.size());
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int n) { return n == 1; }));

  // A box around one chunk: exactly the other points inside it, by brute force.
  const SpillChunk& chunk = distribution.chunks()[distribution.chunks().size() / 2];
  const glm::dvec3 lo(0.2, 0.3, 0.35), hi(0.6, 0.55, 0.7);
  const LoadedPoints box = distribution.loadBox(lo, hi, chunk);
  std::set<uint32_t> expected;
  for (uint32_t s = 0; s < cloud.size(); ++s) {
    const glm::vec3 u(toFrame(cloud.positions[s], frame));
    const uint64_t key = keyOf(u);
    const bool inChunk = key >> (3 * (kMaxLevel - chunk.level)) == chunk.key;
    if (!inChunk && u.x >= lo.x && u.y >= lo.y && u.z >= lo.z && u.x <= hi.x && u.y <= hi.y &&
        u.z <= hi.z)
      expected.insert(s);
  }
  EXPECT_GT(expected.size(), 100u);
  EXPECT_EQ(std::set<uint32_t>(box.source.begin(), box.source.end()), expected);
  EXPECT_EQ(box.source.size(), expected.size());
}

// Convert in core and out of core (hundreds of chunks) and compare the files byte by byte;
// returns the streamed conversion's report.
nlohmann::json expectSameFiles(const PointCloud& cloud, const BuildOptions& options,
                               uint64_t chunkPoints, size_t minimumChunks) {
  test::TempDir dir;
  const nlohmann::json inCore = convertToIso(cloud, dir / "in.iso", options);
  SpillDirectory spill(dir.path());
  const auto raw = spillOf(spill, cloud);
  // Every array of a page or more spilled, and their pages dropped whenever the pager looks (a
  // byte of memory): the stages must read the same values back from the files, however often.
  const nlohmann::json streamed =
      convertSpilled(*raw, spill, {chunkPoints, 1, 4096}, dir / "out.iso", options);
  EXPECT_GE(streamed["out_of_core"]["chunks"].get<size_t>(), minimumChunks);
  EXPECT_GT(streamed["out_of_core"]["spilled_arrays"].get<uint64_t>(), 0u);
  if (minimumChunks > 1) {
    EXPECT_GT(streamed["out_of_core"]["halo_points"].get<uint64_t>(), 0u);
  }
  EXPECT_EQ(streamed["points"], inCore["points"]);
  EXPECT_EQ(streamed["normals"], inCore["normals"]);
  EXPECT_EQ(streamed["octree"], inCore["octree"]);
  EXPECT_EQ(streamed["accuracy"], inCore["accuracy"]);
  const std::vector<std::byte> a = test::readFile(dir / "in.iso"),
                               b = test::readFile(dir / "out.iso");
  EXPECT_GT(a.size(), 1000u);
  EXPECT_TRUE(a == b) << "the streamed file differs from the in-core one";
  return streamed;
}

TEST(OutOfCore, hundredsOfChunksWriteTheSameFileAsInCoreWithoutNormals) {
  // Orientation blocks of 256 points, so that chunks can be small: 100k points in ~300 chunks.
  BuildOptions options;
  options.orientBlockPoints = 256;
  expectSameFiles(test::scanOf("torus", 100000, false, 0.3), options, 300, 200);
}

TEST(OutOfCore, chunkRunsOfTheOctreeStagesWriteTheSameFileInCoreAndOutOfCore) {
  BuildOptions options;
  options.orientBlockPoints = 256;
  options.octreeChunkPoints = 8000;  // chunk jobs of the octree stages, as at 20M points
  options.maxTestedEdge = 24.0;
  const nlohmann::json report =
      expectSameFiles(test::scanOf("torus", 100000, false, 0.3), options, 300, 200);
  EXPECT_GE(report["octree_chunks"]["chunks"].get<size_t>(), 8u);
}

TEST(OutOfCore, sameFileWithInputNormalsSomeFlippedColorsAndDuplicates) {
  PointCloud cloud = test::scanOf("sphere", 60000, true, 0.2, 7);
  cloud.colors.resize(cloud.size());
  std::mt19937 random(3);
  for (size_t i = 0; i < cloud.size(); ++i) {
    cloud.colors[i] = glm::vec3(float(i % 7) / 7.0f, 0.5f, float(i % 3) / 3.0f);
    if (random() % 50 == 0) cloud.normals[i] = -cloud.normals[i];  // to be repaired
    if (random() % 20 == 0) cloud.normals[i] = glm::vec3(0.0f);    // to be estimated
  }
  for (size_t i = 0; i < 3000; ++i) {  // exact duplicates
    cloud.positions.push_back(cloud.positions[i * 11]);
    cloud.normals.push_back(cloud.normals[i * 11]);
    cloud.colors.push_back(cloud.colors[i * 11]);
  }
  BuildOptions options;
  options.orientBlockPoints = 256;
  expectSameFiles(cloud, options, 400, 100);
}

TEST(OutOfCore, texturesAmbientOcclusionAndKeptPointsMakeTheSameFile) {
  test::TempDir dir;
  test::writePpm(dir / "tex.ppm", 8, 8, test::randomImage(8, 8, 2));
  PointCloud cloud = test::scanOf("torus", 40000, true, 0.1, 4);
  BuildOptions options;
  options.orientBlockPoints = 256;
  options.texture = {dir / "tex.ppm", 0.7, 3.0, TextureAt::Points};
  options.occlusion = {true, 8, 0.5};
  options.keepPoints = true;  // copied as they are into the file with occlusion
  options.keptPointsPerChunk = 5000;
  const nlohmann::json report = expectSameFiles(cloud, options, 400, 50);
  EXPECT_EQ(report["texture"]["at"], "points");
  EXPECT_GT(report["occlusion"]["corners"].get<uint64_t>(), 1000u);
  EXPECT_EQ(report["kept_points"]["points"], cloud.size());
  EXPECT_GE(report["kept_points"]["chunks"].get<uint64_t>(), 8u);
  options.texture.at = TextureAt::Corners;
  cloud.colors.assign(cloud.size(), glm::vec3(0.5f, 0.25f, 1.0f));  // multiplied by the texture
  expectSameFiles(cloud, options, 400, 50);
}

TEST(OutOfCore, farOutliersChooseTheFrameAgainAsInCore) {
  PointCloud cloud = test::scanOf("sphere", 40000, false, 0.0, 9);
  cloud.positions.push_back(glm::dvec3(40.0, 3.0, -2.0));
  cloud.positions.push_back(glm::dvec3(-25.0, 60.0, 1.0));
  BuildOptions options;
  options.orientBlockPoints = 128;
  const nlohmann::json streamed = expectSameFiles(cloud, options, 200, 100);
  EXPECT_EQ(streamed["points"]["outliers_removed"], 2);
  EXPECT_EQ(streamed["out_of_core"]["chunks_prepared_again"], 0);  // distributed again instead
}

TEST(OutOfCore, outliersInsideTheBoundsPrepareOnlyTheChunksAroundThemAgain) {
  // Points at the centre of a sphere are outliers that do not hold the bounds: the frame stays,
  // and only the chunks whose boxes held them run again; the file is still the in-core one.
  PointCloud cloud = test::scanOf("sphere", 40000, false, 0.0, 11);
  cloud.positions.push_back(glm::dvec3(0.01, 0.0, 0.0));
  cloud.positions.push_back(glm::dvec3(-0.2, 0.3, 0.1));
  BuildOptions options;
  options.orientBlockPoints = 128;
  const nlohmann::json streamed = expectSameFiles(cloud, options, 200, 100);
  EXPECT_EQ(streamed["points"]["outliers_removed"], 2);
  const size_t again = streamed["out_of_core"]["chunks_prepared_again"].get<size_t>();
  EXPECT_GE(again, 1u);
  EXPECT_LT(again, streamed["out_of_core"]["chunks"].get<size_t>() / 2);
}

// Groups of strays across chunk borders (the groups are joined over all chunks), sparse dust
// inside the bounds and a far group that moves the frame: the same strays, the same file.
TEST(OutOfCore, straysInGroupsAndDustAreFoundAcrossChunksAsInCore) {
  const PointCloud sphere = test::scanOf("sphere", 40000, false, 0.0, 13);
  std::mt19937 random(21);
  std::normal_distribution<double> spread(0.0, 0.01);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto group = [&](PointCloud& cloud, const glm::dvec3& centre, int count) {
    for (int i = 0; i < count; ++i)
      cloud.positions.push_back(centre +
                                glm::dvec3(spread(random), spread(random), spread(random)));
  };
  PointCloud inside = sphere;
  group(inside, glm::dvec3(0.0), 30);               // at the centre: on the borders of 8 chunks
  group(inside, glm::dvec3(0.85, 0.85, 0.85), 12);  // in a corner of the bounds
  for (int i = 0; i < 40; ++i) {                    // dust at least 0.4 inside the sphere
    const glm::dvec3 p(u(random), u(random), u(random));
    if (glm::length(p) < 0.6) inside.positions.push_back(p);
  }
  const size_t insideStrays = inside.size() - sphere.size();
  BuildOptions options;
  options.orientBlockPoints = 128;
  nlohmann::json streamed = expectSameFiles(inside, options, 200, 100);
  EXPECT_EQ(streamed["points"]["outliers_removed"].get<size_t>(), insideStrays);
  EXPECT_GE(streamed["out_of_core"]["chunks_prepared_again"].get<size_t>(), 1u);

  PointCloud far = inside;
  group(far, glm::dvec3(4.0, -3.0, 2.0), 25);
  streamed = expectSameFiles(far, options, 200, 100);
  EXPECT_EQ(streamed["points"]["outliers_removed"].get<size_t>(), insideStrays + 25);
}

TEST(OutOfCore, upOrientationAndASingleChunkMatchToo) {
  BuildOptions options;
  options.orient = OrientMode::Up;
  options.orientBlockPoints = 512;
  expectSameFiles(test::scanOf("plane", 30000, false, 0.2), options, 600, 20);
  BuildOptions defaults;
  expectSameFiles(test::scanOf("cube", 20000, false), defaults, 1u << 30, 1);
}

// An input of one chunk stops after its neighbours while strays are looked for: with none found
// it finishes, with strays inside the bounds it runs again without them; the in-core file both
// times.
TEST(OutOfCore, aSingleChunkWithAndWithoutStraysMatches) {
  BuildOptions options;
  options.orientBlockPoints = 128;
  PointCloud cloud = test::scanOf("sphere", 20000, false, 0.0, 11);
  nlohmann::json streamed = expectSameFiles(cloud, options, 1u << 30, 1);
  EXPECT_EQ(streamed["out_of_core"]["chunks"], 1);
  EXPECT_EQ(streamed["points"]["outliers_removed"], 0);
  EXPECT_EQ(streamed["out_of_core"]["chunks_prepared_again"], 0);
  cloud.positions.push_back(glm::dvec3(0.01, 0.0, 0.0));
  cloud.positions.push_back(glm::dvec3(-0.2, 0.3, 0.1));
  streamed = expectSameFiles(cloud, options, 1u << 30, 1);
  EXPECT_EQ(streamed["out_of_core"]["chunks"], 1);
  EXPECT_EQ(streamed["points"]["outliers_removed"], 2);
  EXPECT_EQ(streamed["out_of_core"]["chunks_prepared_again"], 1);
}

// The inputs' coordinate system is part of the file: the same in core and out of core.
TEST(OutOfCore, theCoordinateSystemIsTheSameInBothFiles) {
  ConvertSource source;
  source.inputs = nlohmann::json::array(
      {{{"file", "a.xyz"}, {"format", "xyz"}, {"points", 1}},
       {{"file", "b.las"},
        {"format", "las 1.4 format 6"},
        {"points", 2},
        {"crs", {{"wkt", "PROJCS[\"b\"]"}, {"epsg", 32612}, {"source", "VLR"}}}},
       {{"file", "c.las"},
        {"format", "las 1.2 format 0"},
        {"points", 3},
        {"crs", {{"wkt", "PROJCS[\"b\"]"}, {"epsg", 32612}, {"source", "EVLR"}}}},
       {{"file", "d.las"},
        {"format", "las 1.2 format 0"},
        {"points", 4},
        {"crs", {{"epsg", 32613}, {"source", "VLR"}}}}});
  const nlohmann::json expected = {{"wkt", "PROJCS[\"b\"]"},
                                   {"epsg", 32612},
                                   {"source", "VLR"},
                                   {"input", "b.las"},
                                   {"differing_inputs", {"d.las"}}};
  EXPECT_EQ(coordinateSystemOf(source.inputs), expected);
  EXPECT_TRUE(coordinateSystemOf(nlohmann::json::array({source.inputs[0]})).is_null());

  const PointCloud cloud = test::scanOf("sphere", 20000, false);
  BuildOptions options;
  options.orientBlockPoints = 512;
  test::TempDir dir;
  convertToIso(cloud, dir / "in.iso", options, source);
  SpillDirectory spill(dir.path());
  const auto raw = spillOf(spill, cloud);
  const nlohmann::json streamed =
      convertSpilled(*raw, spill, {1000, 1, 4096}, dir / "out.iso", options, source);
  EXPECT_GE(streamed["out_of_core"]["chunks"].get<size_t>(), 20u);
  EXPECT_TRUE(test::readFile(dir / "in.iso") == test::readFile(dir / "out.iso"));
  const nlohmann::json metadata = nlohmann::json::parse(Reader::open(dir / "out.iso").metadata());
  EXPECT_EQ(metadata["crs"], expected);
  EXPECT_EQ(metadata["inputs"], source.inputs);
}

TEST(OutOfCore, tinyInputsGiveTheSameFileOrTheSameError) {
  std::mt19937 random(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (size_t n : {1, 2, 3, 4, 7, 12, 40}) {
    PointCloud cloud;
    for (size_t i = 0; i < n; ++i)
      cloud.positions.push_back({u(random), u(random), 0.1 * u(random)});
    test::TempDir dir;
    std::string inCoreError, streamedError;
    try {
      convertToIso(cloud, dir / "in.iso", {});
    } catch (const ConvertError& e) {
      inCoreError = e.what();
    }
    SpillDirectory spill(dir.path());
    const auto raw = spillOf(spill, cloud);
    try {
      convertSpilled(*raw, spill, {1u << 20, 1, 4096}, dir / "out.iso", {});
    } catch (const ConvertError& e) {
      streamedError = e.what();
    }
    EXPECT_EQ(inCoreError, streamedError) << n << " points";
    EXPECT_EQ(n < 3, !inCoreError.empty()) << n << " points: " << inCoreError;
    if (inCoreError.empty()) {
      EXPECT_TRUE(test::readFile(dir / "in.iso") == test::readFile(dir / "out.iso")) << n;
    }
  }
}

TEST(OutOfCore, theSpillDirectoryLeavesNothingBehind) {
  test::TempDir dir;
  {
    SpillDirectory spill(dir.path());
    const auto raw = spillOf(spill, test::scanOf("sphere", 1000, false));
    EXPECT_GT(spill.bytes(), 0u);
    EXPECT_FALSE(std::filesystem::is_empty(dir.path()));
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

}  // namespace
}  // namespace iso

namespace iso {
namespace {

TEST(Progress, inCoreStagesNeverCountPastTheirTotalsWhenOutliersRunThemAgain) {
  PointCloud cloud = test::scanOf("sphere", 40000, false, 0.0, 9);
  cloud.positions.push_back(glm::dvec3(40.0, 3.0, -2.0));  // a far outlier: prepared again
  test::TempDir dir;
  std::FILE* log = std::tmpfile();
  ASSERT_NE(log, nullptr);
  {
    ProgressReporter progress(ProgressMode::Json, log, std::chrono::milliseconds(1));
    ConvertSource source;
    source.progress = &progress;
    const nlohmann::json report = convertToIso(cloud, dir / "out.iso", BuildOptions{}, source);
    EXPECT_EQ(report["points"]["outliers_removed"], 1);
  }
  std::rewind(log);
  std::map<std::string, int> ends;
  size_t updates = 0;
  char line[4096];
  while (std::fgets(line, sizeof line, log)) {
    const nlohmann::json event = nlohmann::json::parse(line);
    ++updates;
    if (event["event"] == "end") ++ends[event["stage"].get<std::string>()];
    if (event.contains("total")) {  // known totals only
      EXPECT_LE(event["done"].get<uint64_t>(), event["total"].get<uint64_t>()) << line;
    }
  }
  std::fclose(log);
  EXPECT_GT(updates, 10u);
  EXPECT_EQ(ends["prepare"], 2);  // each stage run again is its own entry
  EXPECT_EQ(ends["radii"], 2);
}

}  // namespace
}  // namespace iso
