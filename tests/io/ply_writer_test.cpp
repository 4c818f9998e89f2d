// PLY output: what is written reads back (exactly for double positions and float normals, within
// one sRGB code for colors), the header carries the comments, and writes are atomic.
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <random>

#include "pipeline/io/color.h"
#include "pipeline/io/ply.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

PointCloud randomCloud(size_t count, bool normals, bool colors) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> coordinate(-1000.0, 1000.0);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  PointCloud cloud;
  for (size_t i = 0; i < count; ++i) {
    // Large offsets with sub-millimetre detail, as in UTM scans.
    cloud.positions.emplace_back(515000.0 + coordinate(rng), 4918000.0 + coordinate(rng),
                                 coordinate(rng) * 1e-3);
    if (normals) cloud.normals.emplace_back(unit(rng) - 0.5f, unit(rng), -unit(rng));
    if (colors) cloud.colors.emplace_back(unit(rng), unit(rng), unit(rng));
  }
  if (colors) {
    cloud.colors[0] = {0.0f, 1.0f, 0.5f};
    cloud.colors[1] = {-0.2f, 1.7f, 0.0031f};  // out of range: clamped
  }
  return cloud;
}

void expectSameColorCodes(const glm::vec3& written, const glm::vec3& read) {
  for (int c = 0; c < 3; ++c) {
    const int expected = linearToSrgb8(written[c]);
    EXPECT_NEAR(int{linearToSrgb8(read[c])}, expected, 1);
    EXPECT_NEAR(read[c], test::linearOf8(expected), 1e-6);
  }
}

struct RoundTripCase {
  bool binary;
  bool doublePositions;
  bool normals;
  bool colors;
};

class PlyRoundTrip : public testing::TestWithParam<RoundTripCase> {};

TEST_P(PlyRoundTrip, writtenPointsReadBack) {
  const RoundTripCase c = GetParam();
  const PointCloud cloud = randomCloud(2500, c.normals, c.colors);
  test::TempDir dir;
  writePly(dir / "out.ply", cloud,
           {.binary = c.binary, .doublePositions = c.doublePositions, .comments = {}});
  const auto reader = openPointFile(dir / "out.ply");
  EXPECT_EQ(reader->info().format, c.binary ? "ply-binary-le" : "ply-ascii");
  EXPECT_EQ(reader->info().hasNormals, c.normals);
  EXPECT_EQ(reader->info().hasColors, c.colors);
  const PointCloud read = test::readInBatches(dir / "out.ply", {}, nullptr, 777);
  ASSERT_EQ(read.size(), cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    const glm::dvec3 expected =
        c.doublePositions ? cloud.positions[i] : test::roundedToFloat(cloud.positions[i]);
    ASSERT_EQ(read.positions[i], expected) << "point " << i;
    if (c.normals) {
      ASSERT_EQ(read.normals[i], cloud.normals[i]) << "point " << i;
    }
    if (c.colors) expectSameColorCodes(cloud.colors[i], read.colors[i]);
  }
}

INSTANTIATE_TEST_SUITE_P(EncodingsAndAttributes, PlyRoundTrip,
                         testing::Values(RoundTripCase{true, true, true, true},
                                         RoundTripCase{true, false, true, true},
                                         RoundTripCase{false, true, true, true},
                                         RoundTripCase{false, false, false, true},
                                         RoundTripCase{true, true, false, false},
                                         RoundTripCase{false, true, true, false},
                                         RoundTripCase{true, false, false, true}));

TEST(PlyWriter, writesCommentsAsSingleHeaderLines) {
  test::TempDir dir;
  PointCloud cloud;
  cloud.positions = {{1, 2, 3}};
  writePly(dir / "c.ply", cloud,
           {.binary = false, .doublePositions = true, .comments = {"source: scan", "two\nlines"}});
  const std::vector<std::byte> bytes = test::readFile(dir / "c.ply");
  const std::string text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  EXPECT_EQ(text,
            "ply\nformat ascii 1.0\ncomment source: scan\ncomment two lines\nelement vertex 1\n"
            "property double x\nproperty double y\nproperty double z\nend_header\n1 2 3\n");
}

TEST(PlyWriter, writesAnEmptyCloud) {
  test::TempDir dir;
  writePly(dir / "e.ply", PointCloud{});
  EXPECT_EQ(readPointFile(dir / "e.ply").size(), 0u);
}

TEST(PlyWriter, failureNamesTheOutputAndLeavesNothing) {
  test::TempDir dir;
  PointCloud cloud;
  cloud.positions = {{1, 2, 3}};
  try {
    writePly(dir / "missing-folder" / "x.ply", cloud);
    FAIL() << "no error";
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), (dir / "missing-folder" / "x.ply").string());
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(PlyWriter, failedWriteOnFullDiskKeepsTheOldFileAndRemovesTheTemporary) {
  // A file size limit makes write() fail the way a full disk does; a child process keeps the limit
  // from leaking into other tests.
  test::TempDir dir;
  test::writeText(dir / "out.ply", "old");
  const PointCloud cloud = randomCloud(20000, true, true);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    signal(SIGXFSZ, SIG_IGN);
    rlimit limit{64 * 1024, 64 * 1024};
    setrlimit(RLIMIT_FSIZE, &limit);
    int status = 10;
    try {
      writePly(dir / "out.ply", cloud);
    } catch (const FileError& error) {
      status = error.file() == (dir / "out.ply").string() ? 0 : 11;
    } catch (...) {
      status = 12;
    }
    _exit(status);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    names.push_back(entry.path().filename().string());
  EXPECT_EQ(names, std::vector<std::string>{"out.ply"});
  const std::vector<std::byte> old = test::readFile(dir / "out.ply");
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(old.data()), old.size()), "old");
}

TEST(PlyWriter, replacesAnExistingFile) {
  test::TempDir dir;
  test::writeText(dir / "out.ply", "old");
  writePly(dir / "out.ply", randomCloud(10, false, false));
  EXPECT_EQ(readPointFile(dir / "out.ply").size(), 10u);
}

TEST(PlyMeshWriter, meshReadsBackWithFloatVertices) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.1, 0.2, 1.0 / 3.0}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}, {1, 3, 2}};
  test::TempDir dir;
  writePlyMesh(dir / "m.ply", mesh);
  const TriangleMesh read = readPlyMesh(dir / "m.ply");
  ASSERT_EQ(read.vertices.size(), 4u);
  for (size_t i = 0; i < 4; ++i)
    EXPECT_EQ(read.vertices[i], test::roundedToFloat(mesh.vertices[i]));
  EXPECT_EQ(read.triangles, mesh.triangles);
  const auto reader = openPointFile(dir / "m.ply");
  EXPECT_EQ(reader->info().format, "ply-binary-le");
}

}  // namespace
}  // namespace iso
