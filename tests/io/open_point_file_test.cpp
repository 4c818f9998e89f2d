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
  EXPECT_NE(error.find("unknown point file format ('.obj'): it is not PLY (no 'ply' line first), "
                       "LAS (no LASF signature), Draco (no DRACO signature), E57 (no ASTM-E57 "
                       "signature) or PCD (no PCD header), nor text (line 1: 'v' is not a number)"),
            std::string::npos)
      << error;
  EXPECT_NE(error.find("PLY (.ply), LAS 1.0-1.4 (.las), PCD (.pcd), Draco (.drc), text (.xyz .txt "
                       ".pts .csv .asc .neu .xyzrgb .xyzn, or any name with --columns), each "
                       "optionally gzip-compressed (.gz); LAZ (.laz) and E57 (.e57)"),
            std::string::npos)
      << error;
  test::writeText(dir / "b.ply", "1 2 3\n");
  EXPECT_NE(test::readError(dir / "b.ply").find("not a PLY file"), std::string::npos);
  test::writeText(dir / "c.las", "LAS");
  EXPECT_NE(test::readError(dir / "c.las").find("not a LAS file"), std::string::npos);
}

// Scanner and CloudCompare exports come as .asc, .neu, .xyzrgb and names of any other extension:
// those known are text; others are read as text when their content is.
TEST(OpenPointFile, readsTextOfOtherExtensionsByTheirContent) {
  test::TempDir dir;
  const std::vector<std::pair<std::string, std::string>> files = {
      {"a.asc", "1 2 3\n4 5 6\n"},
      {"b.neu", "1 2 3\n4 5 6\n"},
      {"c.XYZRGB", "1 2 3 0 0 1\n4 5 6 1 0.5 0\n"},
      {"d.dat", "X;Y;Z\n1;2;3\n4;5;6\n"},
      {"scan", "# exported\n2\n1,2,3\n4,5,6\n"},
      {"e.txt2", "1\t2\t3\r\n4\t5\t6\r\n"},
      {"f.dat.gz", "1 2 3\n4 5 6\n"},
  };
  for (const auto& [name, text] : files) {
    SCOPED_TRACE(name);
    if (name.ends_with(".gz")) {
      test::writeGzip(dir / name, Bytes().text(text).bytes());
    } else {
      test::writeText(dir / name, text);
    }
    const auto reader = openPointFile(dir / name);
    EXPECT_EQ(reader->info().format, "xyz");
    const PointCloud points = test::readInBatches(dir / name);
    ASSERT_EQ(points.size(), 2u);
    EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
    EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
    EXPECT_EQ(points.hasColors(), name == "c.XYZRGB");
  }
}

// With --columns every file not recognized by its signature (PLY, LAS, Draco) or PCD header is
// read as text, whatever its name.
TEST(OpenPointFile, aColumnSpecReadsAnyExtensionAsText) {
  test::TempDir dir;
  test::writeText(dir / "a.obj", "v 1 2 3\nv 4 5 6\n");
  test::writeText(dir / "b.ply", "1 2 3 9\n");
  EXPECT_NE(test::readError(dir / "a.obj").find("unknown point file format"), std::string::npos);
  const PointCloud obj = readPointFile(dir / "a.obj", {.columns = "_,x,y,z"});
  ASSERT_EQ(obj.size(), 2u);
  EXPECT_EQ(obj.positions[1], glm::dvec3(4, 5, 6));
  EXPECT_NE(test::readError(dir / "b.ply").find("not a PLY file"), std::string::npos);
  EXPECT_EQ(readPointFile(dir / "b.ply", {.columns = "z,y,x,_"}).positions.at(0),
            glm::dvec3(3, 2, 1));
  writePly(dir / "c.dat", threePoints());  // a signature still wins
  EXPECT_EQ(openPointFile(dir / "c.dat", {.columns = "x,y,z"})->info().format, "ply-binary-le");
}

TEST(OpenPointFile, refusingAFileSaysWhatWasTriedAndWhyItIsNotText) {
  test::TempDir dir;
  const std::vector<std::pair<Bytes, std::string>> cases = {
      {Bytes().text("abc").fill(1, 0).text("def"), "byte 3 is 0: binary data, not text"},
      {Bytes(), "the file is empty"},
      {Bytes().text("1 2\n3 4\n"), "line 1 has 2 numbers, fewer than x, y and z"},
      {Bytes().text("# c\nx y z\n1 2 3\n4 5 6 7\n"), "line 4 has 4 numbers, line 3 has 3"},
      {Bytes().text("x y z\nname 1 2\n"), "line 2: 'name' is not a number"},
      {Bytes().text("x y z\n# only names\n"), "no line of numbers in its first 19 bytes"},
  };
  for (const auto& [content, why] : cases) {
    SCOPED_TRACE(why);
    test::writeFile(dir / "scan.bin", content.bytes());
    const std::string error = test::readError(dir / "scan.bin");
    EXPECT_NE(error.find((dir / "scan.bin").string() + ": unknown point file format ('.bin'): it "
                                                       "is not PLY"),
              std::string::npos)
        << error;
    EXPECT_NE(error.find("nor text (" + why + ")"), std::string::npos) << error;
  }
  test::writeText(dir / "noextension", "\x01\x02");
  EXPECT_NE(test::readError(dir / "noextension")
                .find("unknown point file format (a name without extension)"),
            std::string::npos);
}

TEST(OpenPointFile, readsPcdByItsHeaderWhateverTheExtension) {
  test::TempDir dir;
  const std::string header =
      "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
      "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n";
  test::writeText(dir / "scene.dat", header);
  test::writeText(dir / "scene.txt", "# .PCD v0.7 - Point Cloud Data file format\n" + header);
  for (const char* name : {"scene.dat", "scene.txt"}) {
    EXPECT_EQ(openPointFile(dir / name)->info().format, "pcd-ascii") << name;
    EXPECT_EQ(readPointFile(dir / name).positions.at(0), glm::dvec3(1, 2, 3)) << name;
  }
}

TEST(OpenPointFile, refusesAnE57NameWithoutTheE57Signature) {
  test::TempDir dir;
  test::writeText(dir / "scan.e57", "1 2 3\n");
  const std::string error = test::readError(dir / "scan.e57", {.columns = "x,y,z"});
  EXPECT_NE(
      error.find((dir / "scan.e57").string() + ": byte 0: not an E57 file: no ASTM-E57 signature"),
      std::string::npos)
      << error;
}

TEST(OpenPointFile, readsE57FilesByTheirSignatureWhateverTheExtension) {
  const std::filesystem::path sample =
      std::filesystem::path(ISO_TEST_DATA_DIR) / "e57" / "two-scans.e57";
  test::TempDir dir;
  for (const char* name : {"scan.data", "SCAN.E57"}) {
    std::filesystem::copy_file(sample, dir / name);
    EXPECT_EQ(openPointFile(dir / name)->info().format, "e57 1.0 (2 scans)") << name;
    EXPECT_EQ(readPointFile(dir / name).size(), 1000u) << name;
  }
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
