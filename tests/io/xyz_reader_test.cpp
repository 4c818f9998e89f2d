// The text reader: columns given or guessed, separators, comments, a .pts count line, color
// ranges, and errors that name the line and column.
#include <cmath>

#include "pipeline/io/color.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

TEST(XyzReader, guessesPositionsNormalsAndColorsFromTheColumnCount) {
  test::TempDir dir;
  test::writeText(dir / "3.xyz", "1 2 3\n4 5 6\n");
  test::writeText(dir / "6.xyz", "1 2 3 0 0 1\n4 5 6 1 0 0\n");
  test::writeText(dir / "9.xyz", "1 2 3 0 0 1 255 0 10\n4 5 6 1 0 0 0 128 0\n");

  PointCloud points = test::readInBatches(dir / "3.xyz");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
  EXPECT_FALSE(points.hasNormals());

  points = test::readInBatches(dir / "6.xyz");
  ASSERT_TRUE(points.hasNormals());
  EXPECT_EQ(points.normals[0], glm::vec3(0, 0, 1));
  EXPECT_FALSE(points.hasColors());

  const auto reader = openPointFile(dir / "9.xyz");
  EXPECT_EQ(reader->info().format, "xyz");
  EXPECT_TRUE(reader->info().hasNormals && reader->info().hasColors);
  points = test::readInBatches(dir / "9.xyz");
  ASSERT_TRUE(points.hasColors());
  EXPECT_FLOAT_EQ(points.colors[0].r, 1.0f);
  EXPECT_NEAR(points.colors[0].b, test::linearOf8(10), 1e-6);
  EXPECT_NEAR(points.colors[1].g, test::linearOf8(128), 1e-6);
}

// Without --columns, a count that leaves a choice is decided by the values of the first lines
// (colors 0–255 have a value above 1, unit normals none) and by the extension, and said in a note.
TEST(XyzReader, guessesColumnsFromTheValuesOfTheFirstLinesAndTheExtension) {
  struct Case {
    std::string name, text;
    bool hasNormals, hasColors;
    std::string note;  // the guess the note names; empty: no note
  };
  const std::vector<Case> cases = {
      {"i.asc", "1 2 3 -1200\n4 5 6 800\n", false, false, "x,y,z,_"},
      {"c.asc", "1 2 3 0 1 1\n4 5 6 255 128 0\n", false, true, "x,y,z,r,g,b"},
      {"n.asc", "1 2 3 0 0 1\n4 5 6 0.6 0.8 0\n", true, false, "x,y,z,nx,ny,nz"},
      {"u.xyzrgb", "1 2 3 0 0 1\n4 5 6 1 0.5 0\n", false, true, "x,y,z,r,g,b"},
      {"n.xyzn", "1 2 3 0 2 1\n4 5 6 9 0 0\n", true, false, "x,y,z,nx,ny,nz"},
      {"l.pts", "2\n1 2 3 -1200 255 128 0\n4 5 6 300 0 1 2\n", false, true, "x,y,z,_,r,g,b"},
      {"cc.txt", "1 2 3 255 128 0 0 0 1\n4 5 6 0 1 2 1 0 0\n", true, true, "x,y,z,r,g,b,nx,ny,nz"},
      {"s.txt", "1 2 3 0 0 1 255 128 0\n4 5 6 1 0 0 0 1 2\n", true, true, "x,y,z,nx,ny,nz,r,g,b"},
      {"p.txt", "1 2 3\n4 5 6\n", false, false, ""},
  };
  test::TempDir dir;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    test::writeText(dir / c.name, c.text);
    const auto reader = openPointFile(dir / c.name);
    EXPECT_EQ(reader->info().hasNormals, c.hasNormals);
    EXPECT_EQ(reader->info().hasColors, c.hasColors);
    if (c.note.empty()) {
      EXPECT_TRUE(reader->info().notes.empty());
    } else {
      ASSERT_EQ(reader->info().notes.size(), 1u);
      EXPECT_EQ(reader->info().notes[0], "its columns are taken as " + c.note +
                                             " (guessed from its first lines; --columns says "
                                             "others)");
    }
    const PointCloud points = test::readInBatches(dir / c.name);
    ASSERT_EQ(points.size(), 2u);
    EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
    EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
  }
  // The values, where they decide: the PTS layout's colors after its intensity, CloudCompare's
  // colors before its normals, unit-range colors of a .xyzrgb.
  PointCloud points = readPointFile(dir / "l.pts");
  EXPECT_NEAR(points.colors[0].g, test::linearOf8(128), 1e-6);
  EXPECT_NEAR(points.colors[1].b, test::linearOf8(2), 1e-6);
  points = readPointFile(dir / "cc.txt");
  EXPECT_NEAR(points.colors[0].r, 1.0f, 1e-6);
  EXPECT_EQ(points.normals[1], glm::vec3(1, 0, 0));
  points = readPointFile(dir / "u.xyzrgb");
  EXPECT_NEAR(points.colors[1].g, srgbToLinear(0.5f), 1e-6);
}

TEST(XyzReader, readsColorsAsUnitRangeWhenTheFirstLinesHaveNoneAboveOne) {
  test::TempDir dir;
  // 100 lines are sampled; a larger value after them is clamped on the 0–1 scale.
  std::string text = "0 0 0 0.5 1 0.25\n";
  for (int i = 0; i < 99; ++i) text += "0 0 0 0 0 1\n";
  test::writeText(dir / "c.txt", text + "1 1 1 0.2 0.2 7\n");
  const PointCloud points = test::readInBatches(dir / "c.txt", {.columns = "x,y,z,r,g,b"});
  ASSERT_EQ(points.size(), 101u);
  EXPECT_NEAR(points.colors[0].r, srgbToLinear(0.5f), 1e-6);
  EXPECT_FLOAT_EQ(points.colors[0].g, 1.0f);
  EXPECT_FLOAT_EQ(points.colors[100].b, 1.0f);  // 7 on a 0–1 scale: clamped
}

TEST(XyzReader, readsColorsAsBytesWhenAnyOfTheFirstLinesHasOneAboveOne) {
  test::TempDir dir;
  // A first point of dark colors (all at most 1) does not make the file's colors 0–1.
  test::writeText(dir / "d.txt", "0 0 0 1 0 1\n1 1 1 200 100 50\n");
  const PointCloud points = readPointFile(dir / "d.txt", {.columns = "x,y,z,r,g,b"});
  ASSERT_EQ(points.size(), 2u);
  EXPECT_NEAR(points.colors[0].r, test::linearOf8(1), 1e-6);
  EXPECT_NEAR(points.colors[1].g, test::linearOf8(100), 1e-6);
}

TEST(XyzReader, followsAColumnSpecWithSkippedColumns) {
  test::TempDir dir;
  test::writeText(dir / "s.txt", "10 1 2 3 0.7 200 100 50\n");
  const auto reader = openPointFile(dir / "s.txt", {.columns = "_, x, y, z, _, r, g, b"});
  EXPECT_TRUE(reader->info().hasColors);
  EXPECT_FALSE(reader->info().hasNormals);
  const PointCloud points = readPointFile(dir / "s.txt", {.columns = "_,x,y,z,_,r,g,b"});
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
  EXPECT_NEAR(points.colors[0].r, test::linearOf8(200), 1e-6);
  EXPECT_NEAR(points.colors[0].b, test::linearOf8(50), 1e-6);

  const PointCloud reordered = readPointFile(dir / "s.txt", {.columns = "_,z,y,x,nx,ny,nz,_"});
  EXPECT_EQ(reordered.positions[0], glm::dvec3(3, 2, 1));
  EXPECT_EQ(reordered.normals[0], glm::vec3(0.7f, 200, 100));
}

TEST(XyzReader, acceptsCommaSemicolonTabAndMixedSeparators) {
  test::TempDir dir;
  test::writeText(dir / "m.csv", "1,2,3\n4;5;6\n7\t8\t9\n10, 11 ;\t12\n  13 14 15  \r\n");
  const PointCloud points = readPointFile(dir / "m.csv");
  ASSERT_EQ(points.size(), 5u);
  for (size_t i = 0; i < 5; ++i)
    EXPECT_EQ(points.positions[i], glm::dvec3(3 * i + 1, 3 * i + 2, 3 * i + 3));
}

TEST(XyzReader, skipsCommentsBlankLinesAndAColumnNameLine) {
  test::TempDir dir;
  test::writeText(dir / "c.csv",
                  "# exported points\n// another comment\n\nx,y,z\n1,2,3\n  # indented\n4,5,6\n");
  const PointCloud points = readPointFile(dir / "c.csv");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
}

TEST(XyzReader, skipsThePtsCountLineAndDeclaresIt) {
  test::TempDir dir;
  test::writeText(dir / "p.pts", "2\n1.5 2.5 3.5\n-1e3 +2 0\n");
  const auto reader = openPointFile(dir / "p.pts");
  EXPECT_EQ(reader->info().declaredPoints, 2u);
  const PointCloud points = readPointFile(dir / "p.pts");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1.5, 2.5, 3.5));
  EXPECT_EQ(points.positions[1], glm::dvec3(-1000, 2, 0));
}

TEST(XyzReader, errorsNameTheLineAndColumn) {
  test::TempDir dir;
  const std::vector<std::tuple<std::string, std::string, std::string>> cases = {
      {"1 2 3 0 0 1\n1 2 3 0 0 1\n# c\n1 2 3 0 1\n", "", "line 4: expected 6 numbers, found 5"},
      {"1 2 3\n1 2 3 4\n", "", "line 2: expected 3 numbers, found 4"},
      {"1 2 3\n1 abc 3\n", "", "line 2: column 2 (y) is not a number: 'abc'"},
      {"1 2 3 4 5\n", "", "line 1: cannot guess the meaning of 5 columns"},
      {"1 2 3 4 5\n", "", "--columns"},
      {"# c\n1 2 3 0.5 0.5 0.5 0.5\n", "", "line 2: cannot guess the meaning of 7 columns"},
      {"1 2 3 4 5 6 7\n", "x,y,z,_,r,g,b", ""},
      {"1 2 3 4 5 6 x\n", "x,y,z,_,r,g,b", "line 1: column 7 (b) is not a number: 'x'"},
  };
  for (const auto& [text, columns, reason] : cases) {
    SCOPED_TRACE(text);
    test::writeText(dir / "e.xyz", text);
    const std::string error = test::readError(dir / "e.xyz", {.columns = columns});
    if (reason.empty()) {
      EXPECT_EQ(error, "");
    } else {
      EXPECT_NE(error.find(reason), std::string::npos) << error;
    }
  }
}

TEST(XyzReader, rejectsInvalidColumnSpecs) {
  test::TempDir dir;
  test::writeText(dir / "p.xyz", "1 2 3 4 5 6\n");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"x,y", "x, y and z are required"},
      {"x,y,z,2w", "unknown column '2w'"},
      {"x,y,z,w,w", "column 'w' appears twice"},
      {"x,y,z,x", "column 'x' appears twice"},
      {"x,y,z,nx,ny", "all of nx,ny,nz"},
      {"x,y,z,r", "all of r,g,b"},
  };
  for (const auto& [columns, reason] : cases) {
    const std::string error = test::readError(dir / "p.xyz", {.columns = columns});
    EXPECT_NE(error.find(reason), std::string::npos) << columns << ": " << error;
  }
}

TEST(XyzReader, namedValueColumnsAreExtrasWhenAskedAndSkippedOtherwise) {
  test::TempDir dir;
  test::writeText(dir / "v.xyz", "1 2 3 0.5 9 -1e300\n4 5 6 -2.25 8 7\nnan 0 0 1 1 1\n");
  const PointCloud values =
      readPointFile(dir / "v.xyz", {.columns = "x,y,z,temperature,_,gps_time", .keepExtras = true});
  EXPECT_EQ(values.extraNames, (std::vector<std::string>{"temperature", "gps_time"}));
  EXPECT_EQ(values.extras, std::vector<double>({0.5, -1e300, -2.25, 7.0}));
  const PointCloud plain = readPointFile(dir / "v.xyz", {.columns = "x,y,z,temperature,_,gps_time"});
  EXPECT_EQ(plain.size(), 2u);
  EXPECT_TRUE(plain.extras.empty());
  test::writeText(dir / "bad.xyz", "1 2 3 warm\n");
  EXPECT_NE(test::readError(dir / "bad.xyz", {.columns = "x,y,z,temperature", .keepExtras = true})
                .find("column 4 (temperature) is not a number"),
            std::string::npos);
}

TEST(XyzReader, dropsAndCountsNonFinitePoints) {
  test::TempDir dir;
  test::writeText(dir / "n.xyz", "1 2 3\nnan 2 3\n1 inf 3\n1 2 -inf\n4 5 6\n1e999 0 0\n");
  ReadStats stats;
  const PointCloud points = test::readInBatches(dir / "n.xyz", {}, &stats, 1);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
  EXPECT_EQ(stats.pointsRead, 2u);
  EXPECT_EQ(stats.droppedNonFinite, 4u);
}

TEST(XyzReader, readsAnEmptyFileAsNoPoints) {
  test::TempDir dir;
  test::writeText(dir / "e.xyz", "# nothing here\n");
  EXPECT_EQ(readPointFile(dir / "e.xyz").size(), 0u);
}

}  // namespace
}  // namespace iso
