// The readers on real scans from ../shared/data (skipped when that folder is absent). Expected
// values were read from the files independently of the readers.
#include <chrono>
#include <glm/common.hpp>
#include <set>

#include "pipeline/io/ply.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using Triangles = std::vector<std::array<uint32_t, 3>>;

std::filesystem::path sharedData(const std::string& name) {
  return std::filesystem::path(ISO_SHARED_DATA_DIR) / name;
}

#define SKIP_WITHOUT_SHARED_DATA()                                        \
  do {                                                                    \
    if (!std::filesystem::is_directory(ISO_SHARED_DATA_DIR))              \
      GTEST_SKIP() << "no shared data folder at " << ISO_SHARED_DATA_DIR; \
  } while (false)

glm::dvec3 asFloat(double x, double y, double z) { return test::roundedToFloat({x, y, z}); }

TEST(RealData, lionLasHasEightBitColorsTimes256) {
  SKIP_WITHOUT_SHARED_DATA();
  const auto reader = openPointFile(sharedData("lion_rgb.las"));
  EXPECT_EQ(reader->info().format, "las 1.2 format 2");
  EXPECT_TRUE(reader->info().hasColors);
  EXPECT_FALSE(reader->info().crs.has_value());
  ASSERT_EQ(reader->info().notes.size(), 1u);
  EXPECT_NE(reader->info().notes[0].find("8-bit codes times 256"), std::string::npos);
  ReadStats stats;
  const PointCloud points = readPointFile(sharedData("lion_rgb.las"), {}, &stats);
  ASSERT_EQ(points.size(), 341989u);
  EXPECT_EQ(stats.droppedNonFinite, 0u);
  EXPECT_EQ(points.positions.front(), glm::dvec3(-2.544, 2.878, 0.882));
  EXPECT_EQ(points.positions.back(), glm::dvec3(-2.076, 4.023, -0.548));
  // The stored values are 49408, 50688, 52736 and 34816: 193, 198, 206 and 136 times 256.
  EXPECT_NEAR(points.colors.front().r, test::linearOf8(193), 1e-6);
  EXPECT_NEAR(points.colors.front().g, test::linearOf8(198), 1e-6);
  EXPECT_NEAR(points.colors.front().b, test::linearOf8(206), 1e-6);
  EXPECT_NEAR(points.colors.back().b, test::linearOf8(136), 1e-6);
}

// The lone-star scan is in UTM zone 12N, but its LAS file (1.2, format 1) has no VLRs at all: the
// header's VLR count is 0 and its point data starts right after the 227-byte header.
TEST(RealData, loneStarLasDeclaresNoCoordinateSystem) {
  SKIP_WITHOUT_SHARED_DATA();
  const auto reader = openPointFile(sharedData("lone_star_tls_utm.las"));
  EXPECT_EQ(reader->info().format, "las 1.2 format 1");
  EXPECT_FALSE(reader->info().crs.has_value());
  EXPECT_TRUE(reader->info().notes.empty());
}

TEST(RealData, loneStarLasKeepsMillimetresAtUtmCoordinates) {
  SKIP_WITHOUT_SHARED_DATA();
  const PointCloud points = readPointFile(sharedData("lone_star_tls_utm.las"));
  ASSERT_EQ(points.size(), 518862u);
  EXPECT_FALSE(points.hasColors());
  EXPECT_EQ(points.positions.front(), glm::dvec3(515396.1665, 4918348.4715, 2323.85525));
  EXPECT_EQ(points.positions.back(), glm::dvec3(515394.67075, 4918366.2755, 2335.297));
  std::set<double> xs;
  std::set<float> floatXs;
  std::set<int64_t> millimetres;
  for (const glm::dvec3& p : points.positions) {
    EXPECT_NEAR(p.x, 515385.0, 50.0);
    EXPECT_NEAR(p.y, 4918360.0, 50.0);
    xs.insert(p.x);
    floatXs.insert(float(p.x));
    millimetres.insert(std::llround(p.x * 1000.0) % 1000);
  }
  EXPECT_EQ(xs.size(), 91212u);  // float positions would keep 1039 of them
  EXPECT_EQ(floatXs.size(), 1039u);
  EXPECT_EQ(millimetres.size(), 1000u);  // every millimetre fraction occurs
}

TEST(RealData, bunnyHasItsVerticesAndTriangles) {
  SKIP_WITHOUT_SHARED_DATA();
  const PointCloud points = readPointFile(sharedData("bunny_zipper.ply"));
  ASSERT_EQ(points.size(), 35947u);
  EXPECT_FALSE(points.hasNormals());
  EXPECT_EQ(points.positions.front(), asFloat(-0.0378297, 0.12794, 0.00447467));
  EXPECT_EQ(points.positions.back(), asFloat(-0.0400442, 0.15362, -0.00816685));

  const TriangleMesh mesh = readPlyMesh(sharedData("bunny_zipper.ply"));
  EXPECT_EQ(mesh.vertices.size(), 35947u);
  ASSERT_EQ(mesh.triangles.size(), 69451u);
  EXPECT_EQ(mesh.triangles.back(), (std::array<uint32_t, 3>{17277, 17346, 17345}));
}

TEST(RealData, parasaurolophusHasNormals) {
  SKIP_WITHOUT_SHARED_DATA();
  const PointCloud points = readPointFile(sharedData("parasaurolophus_normals.ply"));
  ASSERT_EQ(points.size(), 28291u);
  ASSERT_TRUE(points.hasNormals());
  EXPECT_EQ(points.positions.front(), asFloat(-46.9977, -13.4493, -686.008));
  EXPECT_EQ(points.normals.front(), glm::vec3(1.13992f, -0.728988f, -2.52818f));
  EXPECT_EQ(points.normals.back(), glm::vec3(0.822641f, 1.41742f, 5.9841f));
}

TEST(RealData, kittenXyzHasNormals) {
  SKIP_WITHOUT_SHARED_DATA();
  const PointCloud points = readPointFile(sharedData("kitten_normals.xyz"));
  ASSERT_EQ(points.size(), 5210u);
  ASSERT_TRUE(points.hasNormals());
  EXPECT_EQ(points.positions.front(), glm::dvec3(-0.0721898, -0.159749, -0.108444));
  EXPECT_EQ(points.normals.back(), glm::vec3(-0.224494f, 0.265859f, -0.937508f));
}

TEST(RealData, tableScenePcdIsBinaryCompressed) {
  SKIP_WITHOUT_SHARED_DATA();
  const auto reader = openPointFile(sharedData("table_scene_lms400.pcd"));
  EXPECT_EQ(reader->info().format, "pcd-binary-compressed");
  EXPECT_EQ(reader->info().declaredPoints, 460400u);
  const PointCloud points = readPointFile(sharedData("table_scene_lms400.pcd"));
  ASSERT_EQ(points.size(), 460400u);  // no NaN points in this scan
  EXPECT_FALSE(points.hasNormals() || points.hasColors());
  glm::dvec3 lo(1e300), hi(-1e300);
  for (const glm::dvec3& p : points.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  // A table scene, a metre or a few across (a misread field would give nonsense extents).
  for (int a = 0; a < 3; ++a) {
    EXPECT_LT(hi[a] - lo[a], 5.0) << a;
    EXPECT_GT(hi[a] - lo[a], 0.5) << a;
  }
  // Batches of any size give the same points.
  const PointCloud batched = test::readInBatches(sharedData("table_scene_lms400.pcd"));
  EXPECT_TRUE(batched.positions == points.positions);
}

TEST(RealData, dragonMeshReadsQuickly) {
  SKIP_WITHOUT_SHARED_DATA();
  const auto start = std::chrono::steady_clock::now();
  const TriangleMesh mesh = readPlyMesh(sharedData("dragon_vrip.ply.gz"));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("seconds", std::to_string(seconds));
  ASSERT_EQ(mesh.vertices.size(), 437645u);
  ASSERT_EQ(mesh.triangles.size(), 871414u);
  EXPECT_EQ(mesh.vertices.front(), asFloat(0.032027, 0.056575, -0.0503644));
  EXPECT_EQ(mesh.vertices.back(), asFloat(0.0437841, 0.0798208, 0.0205537));
  EXPECT_EQ(mesh.triangles.front(), (std::array<uint32_t, 3>{2, 37, 0}));
  EXPECT_EQ(mesh.triangles.back(), (std::array<uint32_t, 3>{435598, 435560, 435559}));
  // Generous for a loaded machine; about a second is expected in a release build.
  EXPECT_LT(seconds, 10.0);
}

}  // namespace
}  // namespace iso
