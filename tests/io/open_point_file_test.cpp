// Choosing the reader (content before extension), gzip input, the batch contract, and errors for
// files that cannot be read at all.
#include "pipeline/io/ply.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using test::Bytes;

PointCloud threePoints() {
  PointCloud cloud;
  cloud.positions = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  cloud.normals = {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}};
  return cloud;
}

TEST(OpenPointFile, choosesTheReaderByContentBeforeExtension) {
  test::TempDir dir;
  writePly(dir / "really-ply.xyz", threePoints());
  EXPECT_EQ(openPointFile(dir / "really-ply.xyz")->info().format, "ply-binary-le");

  test::writeText(dir / "points.ply.txt", "1 2 3\n");
  EXPECT_EQ(openPointFile(dir / "points.ply.txt")->info().format, "xyz");
}

TEST(OpenPointFile, choosesTextByExtensionInAnyCase) {
  test::TempDir dir;
  for (const char* name : {"a.xyz", "b.TXT", "c.pts", "d.Csv"}) {
    test::writeText(dir / name, "1 2 3\n");
    EXPECT_EQ(readPointFile(dir / name).size(), 1u) << name;
  }
}

TEST(OpenPointFile, rejectsUnknownFormatsListingTheSupportedOnes) {
  test::TempDir dir;
  test::writeText(dir / "a.obj", "v 1 2 3\n");
  const std::string error = test::readError(dir / "a.obj");
  EXPECT_NE(error.find("unknown point file format: '.obj'"), std::string::npos) << error;
  EXPECT_NE(error.find("PLY (.ply), LAS 1.0-1.4 (.las), PCD (.pcd), Draco (.drc), text (.xyz .txt .pts .csv)"),
            std::string::npos)
      << error;
  test::writeText(dir / "b.ply", "1 2 3\n");
  EXPECT_NE(test::readError(dir / "b.ply").find("not a PLY file"), std::string::npos);
  test::writeText(dir / "c.las", "LAS");
  EXPECT_NE(test::readError(dir / "c.las").find("not a LAS file"), std::string::npos);
}

TEST(OpenPointFile, missingFilesAndDirectoriesAreFileErrors) {
  test::TempDir dir;
  try {
    openPointFile(dir / "absent.ply");
    FAIL() << "no error";
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), (dir / "absent.ply").string());
    EXPECT_NE(error.reason().find("cannot open"), std::string::npos);
  }
  std::filesystem::create_directory(dir / "folder.ply");
  EXPECT_NE(test::readError(dir / "folder.ply").find("is a directory"), std::string::npos);
}

TEST(OpenPointFile, readsGzipCompressedFilesTransparently) {
  test::TempDir dir;
  writePly(dir / "p.ply", threePoints());
  test::writeGzip(dir / "p.ply.gz", test::readFile(dir / "p.ply"));
  test::writeGzip(dir / "t.xyz.gz", Bytes().text("1 2 3 0 0 1\n4 5 6 0 1 0\n").bytes());

  const PointCloud ply = readPointFile(dir / "p.ply.gz");
  ASSERT_EQ(ply.size(), 3u);
  EXPECT_EQ(ply.positions[2], glm::dvec3(7, 8, 9));
  EXPECT_EQ(ply.normals[2], glm::vec3(1, 0, 0));
  const PointCloud text = readPointFile(dir / "t.xyz.gz");
  ASSERT_EQ(text.size(), 2u);
  EXPECT_EQ(text.normals[1], glm::vec3(0, 1, 0));
}

TEST(OpenPointFile, truncatedGzipDataIsAFileError) {
  test::TempDir dir;
  PointCloud cloud;
  for (int i = 0; i < 5000; ++i) cloud.positions.emplace_back(i, 2 * i, 3 * i);
  writePly(dir / "p.ply", cloud, {.binary = false, .doublePositions = true, .comments = {}});
  test::writeGzip(dir / "p.ply.gz", test::readFile(dir / "p.ply"));
  std::vector<std::byte> gz = test::readFile(dir / "p.ply.gz");
  gz.resize(gz.size() / 2);
  test::writeFile(dir / "cut.ply.gz", gz);
  EXPECT_NE(test::readError(dir / "cut.ply.gz").find("truncated .gz file"), std::string::npos)
      << test::readError(dir / "cut.ply.gz");
}

TEST(OpenPointFile, readAppendsAtMostTheRequestedPointsAndStopsWithZero) {
  test::TempDir dir;
  PointCloud cloud;
  for (int i = 0; i < 10; ++i) cloud.positions.emplace_back(i, 0, 0);
  writePly(dir / "p.ply", cloud);
  const auto reader = openPointFile(dir / "p.ply");
  PointCloud out;
  out.positions.push_back({-1, -1, -1});  // read() appends; it does not clear
  EXPECT_EQ(reader->read(out, 4), 4u);
  EXPECT_EQ(reader->read(out, 4), 4u);
  EXPECT_EQ(reader->read(out, 4), 2u);
  EXPECT_EQ(reader->read(out, 4), 0u);
  ASSERT_EQ(out.size(), 11u);
  EXPECT_EQ(out.positions[10], glm::dvec3(9, 0, 0));
  EXPECT_EQ(reader->stats().pointsRead, 10u);
}

TEST(OpenPointFile, readPointFileReportsStats) {
  test::TempDir dir;
  test::writeText(dir / "n.xyz", "1 2 3\nnan 0 0\n4 5 6\n");
  ReadStats stats;
  EXPECT_EQ(readPointFile(dir / "n.xyz", {}, &stats).size(), 2u);
  EXPECT_EQ(stats.pointsRead, 2u);
  EXPECT_EQ(stats.droppedNonFinite, 1u);
}

}  // namespace
}  // namespace iso
