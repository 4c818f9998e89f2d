// The PLY point reader: ASCII and binary encodings, properties in any order and of any type, lists
// and other elements skipped, malformed and truncated files rejected with FileError.
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "pipeline/io/color.h"
#include "pipeline/io/ply.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using test::Bytes;

TEST(PlyReader, readsAsciiPositionsNormalsAndColors) {
  test::TempDir dir;
  test::writeText(dir / "a.ply",
                  "ply\nformat ascii 1.0\ncomment made by hand\nobj_info nothing\n"
                  "element vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                  "property float nx\nproperty float ny\nproperty float nz\n"
                  "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
                  "1.5 -2 3e2 0 0 1 255 0 128\n"
                  "0.25 0.5 0.75 1 0 0 10 20 30\n");
  const auto reader = openPointFile(dir / "a.ply");
  EXPECT_EQ(reader->info().format, "ply-ascii");
  EXPECT_EQ(reader->info().declaredPoints, 2u);
  EXPECT_TRUE(reader->info().hasNormals);
  EXPECT_TRUE(reader->info().hasColors);
  const PointCloud points = test::readInBatches(dir / "a.ply");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1.5, -2.0, 300.0));
  EXPECT_EQ(points.positions[1], glm::dvec3(0.25, 0.5, 0.75));
  EXPECT_EQ(points.normals[0], glm::vec3(0, 0, 1));
  EXPECT_EQ(points.normals[1], glm::vec3(1, 0, 0));
  EXPECT_FLOAT_EQ(points.colors[0].r, 1.0f);
  EXPECT_FLOAT_EQ(points.colors[0].g, 0.0f);
  EXPECT_NEAR(points.colors[0].b, test::linearOf8(128), 1e-6);
  EXPECT_NEAR(points.colors[1].g, test::linearOf8(20), 1e-6);
}

TEST(PlyReader, readsBigEndianBinaryWithPropertiesInAnyOrder) {
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty uchar blue\n"
      "property double z\nproperty float nz\nproperty short intensity\nproperty float y\n"
      "property uchar green\nproperty float nx\nproperty double x\nproperty uchar red\n"
      "property float ny\nend_header\n");
  for (int i = 0; i < 2; ++i) {
    file.be<uint8_t>(uint8_t(30 + i)).be(3.25 + i).be(0.5f).be<int16_t>(-7).be(2.5f + float(i));
    file.be<uint8_t>(20).be(-1.0f).be(1e6 + i).be<uint8_t>(10).be(0.25f);
  }
  test::writeFile(dir / "be.ply", file.bytes());
  const auto reader = openPointFile(dir / "be.ply");
  EXPECT_EQ(reader->info().format, "ply-binary-be");
  const PointCloud points = readPointFile(dir / "be.ply");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1e6, 2.5, 3.25));
  EXPECT_EQ(points.positions[1], glm::dvec3(1e6 + 1, 3.5, 4.25));
  EXPECT_EQ(points.normals[1], glm::vec3(-1.0f, 0.25f, 0.5f));
  EXPECT_NEAR(points.colors[1].r, test::linearOf8(10), 1e-6);
  EXPECT_NEAR(points.colors[1].g, test::linearOf8(20), 1e-6);
  EXPECT_NEAR(points.colors[1].b, test::linearOf8(31), 1e-6);
}

TEST(PlyReader, readsEveryScalarTypeNameForCoordinates) {
  // Each row: the type names of x, y, z and the bytes of the values 1, 2, 3 written in that type.
  const std::vector<std::array<std::string, 3>> typeSets = {
      {"char", "uchar", "short"},    {"int8", "uint8", "int16"}, {"ushort", "int", "uint"},
      {"uint16", "int32", "uint32"}, {"float", "double", "int"}, {"float32", "float64", "char"}};
  const auto put = [](Bytes& bytes, const std::string& type, int value) {
    if (type == "char" || type == "int8") bytes.le(int8_t(value));
    if (type == "uchar" || type == "uint8") bytes.le(uint8_t(value));
    if (type == "short" || type == "int16") bytes.le(int16_t(value));
    if (type == "ushort" || type == "uint16") bytes.le(uint16_t(value));
    if (type == "int" || type == "int32") bytes.le(int32_t(value));
    if (type == "uint" || type == "uint32") bytes.le(uint32_t(value));
    if (type == "float" || type == "float32") bytes.le(float(value));
    if (type == "double" || type == "float64") bytes.le(double(value));
  };
  test::TempDir dir;
  for (const auto& types : typeSets) {
    SCOPED_TRACE(types[0] + " " + types[1] + " " + types[2]);
    Bytes file;
    file.text("ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty " + types[0] +
              " x\nproperty " + types[1] + " y\nproperty " + types[2] + " z\nend_header\n");
    put(file, types[0], 1);
    put(file, types[1], 2);
    put(file, types[2], 3);
    test::writeFile(dir / "t.ply", file.bytes());
    const PointCloud points = readPointFile(dir / "t.ply");
    ASSERT_EQ(points.size(), 1u);
    EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
  }
}

TEST(PlyReader, readsSignedNegativeValuesOfIntegerTypes) {
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty char x\n"
      "property short y\nproperty int z\nend_header\n");
  file.le<int8_t>(-128).le<int16_t>(-32768).le<int32_t>(std::numeric_limits<int32_t>::min());
  test::writeFile(dir / "s.ply", file.bytes());
  const PointCloud points = readPointFile(dir / "s.ply");
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points.positions[0], glm::dvec3(-128, -32768, -2147483648.0));
}

TEST(PlyReader, skipsListPropertiesInsideTheVertexElement) {
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property list uchar int neighbours\nproperty float y\n"
      "property list ushort double weights\nproperty float z\nend_header\n");
  for (int i = 0; i < 3; ++i) {
    file.le(float(i)).le<uint8_t>(uint8_t(i)).fill(size_t(4 * i), 0xEE).le(float(10 + i));
    file.le<uint16_t>(uint16_t(2 - i)).fill(size_t(8 * (2 - i)), 0xDD).le(float(20 + i));
  }
  test::writeFile(dir / "l.ply", file.bytes());
  const PointCloud points = test::readInBatches(dir / "l.ply", {}, nullptr, 2);
  ASSERT_EQ(points.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(points.positions[i], glm::dvec3(i, 10 + i, 20 + i));
}

TEST(PlyReader, skipsAsciiListPropertiesInsideTheVertexElement) {
  test::TempDir dir;
  test::writeText(dir / "l.ply",
                  "ply\nformat ascii 1.0\nelement vertex 2\nproperty list uchar int ids\n"
                  "property float x\nproperty float y\nproperty float z\nend_header\n"
                  "3 7 8 9 1 2 3\n0 4 5 6\n");
  const PointCloud points = readPointFile(dir / "l.ply");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
  EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
}

// A binary file whose face element (lists) and an extra element come before the vertices.
Bytes facesBeforeVertices() {
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement face 2\n"
      "property list uchar int vertex_indices\nproperty uchar flags\n"
      "element camera 1\nproperty double px\nproperty list uint float view\n"
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
  file.le<uint8_t>(3).le(0).le(1).le(2).le<uint8_t>(9);
  file.le<uint8_t>(4).le(0).le(1).le(2).le(1).le<uint8_t>(9);
  file.le(1.0).le<uint32_t>(5).fill(20, 0x7F);
  for (int i = 0; i < 3; ++i) file.le(float(i)).le(float(-i)).le(0.5f * float(i));
  return file;
}

TEST(PlyReader, skipsBinaryElementsWithListsBeforeTheVertexElement) {
  test::TempDir dir;
  test::writeFile(dir / "f.ply", facesBeforeVertices().bytes());
  const PointCloud points = readPointFile(dir / "f.ply");
  ASSERT_EQ(points.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(points.positions[i], glm::dvec3(i, -i, 0.5 * i));
}

TEST(PlyReader, skipsAsciiElementsBeforeTheVertexElement) {
  test::TempDir dir;
  test::writeText(dir / "f.ply",
                  "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n"
                  "element vertex 1\nproperty double x\nproperty double y\nproperty double z\n"
                  "end_header\n3 0 0 0\n4 0 0 0 0\n7 8 9\n");
  const PointCloud points = readPointFile(dir / "f.ply");
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points.positions[0], glm::dvec3(7, 8, 9));
}

TEST(PlyReader, doesNotReadElementsAfterTheVertexElement) {
  // The face element is cut short; the point reader must not care.
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1000\n"
      "property list uchar int vertex_indices\nend_header\n");
  file.le(1.0f).le(2.0f).le(3.0f).le<uint8_t>(3).le(0);
  test::writeFile(dir / "v.ply", file.bytes());
  const PointCloud points = readPointFile(dir / "v.ply");
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
}

// A PLY file of the given encoding with one vertex element of these scalar properties (type,
// name) and rows, and a face element of only a `list uchar int` index list named `indexList`,
// before or after the vertices.
struct PlyProperty {
  std::string type, name;
};

void putValue(Bytes& b, const std::string& encoding, const std::string& type, double v) {
  const bool big = encoding == "binary_big_endian";
  const auto put = [&](auto value) { big ? b.be(value) : b.le(value); };
  if (type == "uchar") return put(uint8_t(v));
  if (type == "ushort") return put(uint16_t(v));
  if (type == "int") return put(int32_t(v));
  if (type == "float") return put(float(v));
  put(v);  // double
}

Bytes plyWithFaces(const std::string& encoding, const std::vector<PlyProperty>& properties,
                   const std::vector<std::vector<double>>& rows, const std::string& indexList,
                   const std::vector<std::vector<int>>& faces, bool facesFirst) {
  std::string header = "ply\nformat " + encoding + " 1.0\n";
  std::string vertexHeader = "element vertex " + std::to_string(rows.size()) + "\n";
  for (const PlyProperty& p : properties)
    vertexHeader += "property " + p.type + " " + p.name + "\n";
  const std::string faceHeader = "element face " + std::to_string(faces.size()) +
                                 "\nproperty list uchar int " + indexList + "\n";
  header += facesFirst ? faceHeader + vertexHeader : vertexHeader + faceHeader;
  Bytes file;
  file.text(header + "end_header\n");
  const auto writeVertices = [&] {
    for (const std::vector<double>& row : rows) {
      for (size_t i = 0; i < row.size(); ++i) {
        if (encoding != "ascii") {
          putValue(file, encoding, properties[i].type, row[i]);
          continue;
        }
        std::ostringstream text;
        text << std::setprecision(17) << row[i] << (i + 1 < row.size() ? " " : "\n");
        file.text(text.str());
      }
    }
  };
  const auto writeFaces = [&] {
    for (const std::vector<int>& face : faces) {
      if (encoding == "ascii") {
        std::string line = std::to_string(face.size());
        for (int index : face) line += " " + std::to_string(index);
        file.text(line + "\n");
        continue;
      }
      putValue(file, encoding, "uchar", double(face.size()));
      for (int index : face) putValue(file, encoding, "int", index);
    }
  };
  if (facesFirst) writeFaces();
  writeVertices();
  if (!facesFirst) writeFaces();
  return file;
}

// Meshes as exported by scanners and MeshLab: faces holding only their index list (named
// vertex_indices or vertex_index), before or after the vertices, whose properties come in any
// order with unknown ones between; in every encoding, for the point and the mesh reader.
TEST(PlyReader, readsOddPropertyOrdersAndIndexOnlyFacesInEveryEncoding) {
  const std::vector<PlyProperty> properties = {
      {"float", "nx"}, {"uchar", "red"},  {"double", "z"},         {"float", "quality"},
      {"float", "y"},  {"double", "x"},   {"float", "ny"},         {"uchar", "green"},
      {"float", "nz"}, {"uchar", "blue"}, {"ushort", "confidence"}};
  // nx red z quality y x ny green nz blue confidence
  const std::vector<std::vector<double>> rows = {
      {0, 255, 3.25, 0.5, -2.5, 515000.125, 0, 10, 1, 20, 7},
      {1, 0, -1e-3, 1.5, 0.75, -4.0, 0, 128, 0, 30, 65535},
      {0, 64, 7, -2, 100.5, 1e6, -1, 1, 0, 2, 0}};
  const std::vector<std::vector<int>> faces = {{0, 1, 2}, {2, 1, 0, 1}};
  test::TempDir dir;
  for (const std::string encoding : {"ascii", "binary_little_endian", "binary_big_endian"})
    for (const std::string indexList : {"vertex_indices", "vertex_index"})
      for (const bool facesFirst : {false, true}) {
        SCOPED_TRACE(encoding + " " + indexList + (facesFirst ? ", faces first" : ""));
        const Bytes file = plyWithFaces(encoding, properties, rows, indexList, faces, facesFirst);
        test::writeFile(dir / "m.ply", file.bytes());
        const PointCloud points =
            test::readInBatches(dir / "m.ply", {.columns = "", .keepExtras = true}, nullptr, 2);
        ASSERT_EQ(points.size(), 3u);
        ASSERT_EQ(points.extraNames, (std::vector<std::string>{"quality", "confidence"}));
        for (size_t i = 0; i < 3; ++i) {
          const std::vector<double>& r = rows[i];
          EXPECT_EQ(points.positions[i], glm::dvec3(r[5], r[4], r[2]));
          EXPECT_EQ(points.normals[i], glm::vec3(r[0], r[6], r[8]));
          EXPECT_NEAR(points.colors[i].r, test::linearOf8(int(r[1])), 1e-6);
          EXPECT_NEAR(points.colors[i].g, test::linearOf8(int(r[7])), 1e-6);
          EXPECT_NEAR(points.colors[i].b, test::linearOf8(int(r[9])), 1e-6);
          EXPECT_EQ(points.extras[2 * i], float(r[3]));
          EXPECT_EQ(points.extras[2 * i + 1], float(r[10]));
        }
        const TriangleMesh mesh = readPlyMesh(dir / "m.ply");
        ASSERT_EQ(mesh.vertices.size(), 3u);
        EXPECT_EQ(mesh.vertices[1], glm::dvec3(-4.0, 0.75, -1e-3));
        EXPECT_EQ(mesh.triangles,
                  (std::vector<std::array<uint32_t, 3>>{{0, 1, 2}, {2, 1, 0}, {2, 0, 1}}));
      }
}

// "nx red z y x": one normal and one color component are neither normals nor colors; the
// positions are read wherever they are.
TEST(PlyReader, readsPositionsAfterIncompleteNormalsAndColorsInEveryEncoding) {
  const std::vector<PlyProperty> properties = {
      {"float", "nx"}, {"uchar", "red"}, {"double", "z"}, {"float", "y"}, {"double", "x"}};
  const std::vector<std::vector<double>> rows = {{0.5, 200, 1.125, 2.5, 3.75},
                                                 {-1, 3, -7, 8.25, -9.5}};
  test::TempDir dir;
  for (const std::string encoding : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(encoding);
    test::writeFile(
        dir / "p.ply",
        plyWithFaces(encoding, properties, rows, "vertex_indices", {{0, 1, 0}}, false).bytes());
    const auto reader = openPointFile(dir / "p.ply");
    EXPECT_FALSE(reader->info().hasNormals);
    EXPECT_FALSE(reader->info().hasColors);
    const PointCloud points = readPointFile(dir / "p.ply");
    ASSERT_EQ(points.size(), 2u);
    EXPECT_EQ(points.positions[0], glm::dvec3(3.75, 2.5, 1.125));
    EXPECT_EQ(points.positions[1], glm::dvec3(-9.5, 8.25, -7));
  }
}

TEST(PlyReader, decodesSixteenBitAndFloatColorsAndColorAliases) {
  test::TempDir dir;
  Bytes ushortColors;
  ushortColors.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nproperty ushort r\nproperty ushort g\n"
      "property ushort b\nend_header\n");
  ushortColors.le(0.0f).le(0.0f).le(0.0f).le<uint16_t>(65535).le<uint16_t>(0).le<uint16_t>(32768);
  test::writeFile(dir / "u.ply", ushortColors.bytes());
  PointCloud points = readPointFile(dir / "u.ply");
  ASSERT_EQ(points.colors.size(), 1u);
  EXPECT_FLOAT_EQ(points.colors[0].r, 1.0f);
  EXPECT_FLOAT_EQ(points.colors[0].g, 0.0f);
  EXPECT_NEAR(points.colors[0].b, srgbToLinear(32768.0f / 65535.0f), 1e-6);

  test::writeText(dir / "f.ply",
                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nproperty float diffuse_red\nproperty float diffuse_green\n"
                  "property float diffuse_blue\nend_header\n0 0 0 0.5 1.5 -0.5\n");
  points = readPointFile(dir / "f.ply");
  ASSERT_EQ(points.colors.size(), 1u);
  EXPECT_NEAR(points.colors[0].r, srgbToLinear(0.5f), 1e-6);
  EXPECT_FLOAT_EQ(points.colors[0].g, 1.0f);  // clamped
  EXPECT_FLOAT_EQ(points.colors[0].b, 0.0f);
}

TEST(PlyReader, ignoresIncompleteNormalsAndColors) {
  test::TempDir dir;
  test::writeText(dir / "p.ply",
                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nproperty float nx\nproperty uchar red\nend_header\n"
                  "1 2 3 4 5\n");
  const auto reader = openPointFile(dir / "p.ply");
  EXPECT_FALSE(reader->info().hasNormals);
  EXPECT_FALSE(reader->info().hasColors);
  EXPECT_EQ(readPointFile(dir / "p.ply").positions.at(0), glm::dvec3(1, 2, 3));
}

// A vertex element with extras between and after the standard properties, in each encoding.
struct PropertySpec {
  std::string type, name;
};
const std::vector<PropertySpec> kPropertiesWithExtras = {
    {"float", "x"},        {"ushort", "intensity"}, {"float", "y"},    {"float", "confidence"},
    {"double", "z"},       {"float", "nx"},         {"float", "ny"},   {"float", "nz"},
    {"uchar", "red"},      {"uchar", "green"},      {"uchar", "blue"}, {"char", "scalar_class"},
    {"double", "quality"}, {"int", "scalar_time"}};
const std::vector<std::string> kExtraNames = {"intensity", "confidence", "scalar_class", "quality",
                                              "scalar_time"};
constexpr int kVerticesWithExtras = 5;

double valueWithExtras(int vertex, const std::string& name) {
  const double i = vertex;
  if (name == "x") return i;
  if (name == "y") return -i;
  if (name == "z") return 1e6 + i;
  if (name == "nz" || name == "blue") return 1;
  if (name == "nx" || name == "ny") return 0;
  if (name == "red" || name == "green") return 40 * i;
  if (name == "intensity") return 1000 * i + 7;
  if (name == "confidence") return 0.25 * i;
  if (name == "scalar_class") return i - 3;
  if (name == "quality") return 0.1 * i;
  return 100000 * i - 7;  // scalar_time
}

void putValue(Bytes& bytes, const std::string& type, double value, bool isBigEndian) {
  const auto put = [&](auto typed) { isBigEndian ? bytes.be(typed) : bytes.le(typed); };
  if (type == "char") put(int8_t(value));
  if (type == "uchar") put(uint8_t(value));
  if (type == "ushort") put(uint16_t(value));
  if (type == "int") put(int32_t(value));
  if (type == "float") put(float(value));
  if (type == "double") put(value);
}

// The file in `format` (ascii, binary_little_endian, binary_big_endian), with a list property
// after y when withList (which moves binary decoding off the fixed-record path).
Bytes fileWithExtras(const std::string& format, bool withList) {
  Bytes file;
  file.text("ply\nformat " + format + " 1.0\nelement vertex " +
            std::to_string(kVerticesWithExtras) + "\n");
  for (const PropertySpec& property : kPropertiesWithExtras) {
    file.text("property " + property.type + " " + property.name + "\n");
    if (withList && property.name == "y") file.text("property list uchar int ids\n");
  }
  file.text("end_header\n");
  const bool isAscii = format == "ascii";
  for (int vertex = 0; vertex < kVerticesWithExtras; ++vertex) {
    for (const PropertySpec& property : kPropertiesWithExtras) {
      const double value = valueWithExtras(vertex, property.name);
      if (isAscii) {
        std::ostringstream text;
        text << std::setprecision(17) << value << ' ';
        file.text(text.str());
      } else {
        putValue(file, property.type, value, format == "binary_big_endian");
      }
      if (withList && property.name == "y") {
        if (isAscii) file.text("2 5 6 ");
        if (!isAscii) putValue(file, "uchar", 2, format == "binary_big_endian");
        if (!isAscii) file.fill(8, 0xAB);
      }
    }
    if (isAscii) file.text("\n");
  }
  return file;
}

// The type of an extra property, and a value as that type holds it (extras are doubles).
std::string extraType(const std::string& name) {
  for (const PropertySpec& p : kPropertiesWithExtras)
    if (p.name == name) return p.type;
  return "";
}
double storedAs(const std::string& type, double value) {
  return type == "float" || type == "float32" ? double(float(value)) : value;
}

TEST(PlyReader, keepsExtrasInHeaderOrderInEveryEncoding) {
  test::TempDir dir;
  ReadOptions options;
  options.keepExtras = true;
  for (const std::string format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    for (const bool withList : {false, true}) {
      SCOPED_TRACE(format + (withList ? " with a list" : ""));
      test::writeFile(dir / "e.ply", fileWithExtras(format, withList).bytes());
      EXPECT_EQ(openPointFile(dir / "e.ply", options)->info().extraNames, kExtraNames);
      const PointCloud points = test::readInBatches(dir / "e.ply", options, nullptr, 2);
      ASSERT_EQ(points.size(), size_t(kVerticesWithExtras));
      EXPECT_EQ(points.extraNames, kExtraNames);
      ASSERT_EQ(points.extraCount(), kExtraNames.size());
      ASSERT_EQ(points.extras.size(), points.size() * kExtraNames.size());
      for (int vertex = 0; vertex < kVerticesWithExtras; ++vertex) {
        EXPECT_EQ(points.positions[vertex], glm::dvec3(vertex, -vertex, 1e6 + vertex));
        EXPECT_EQ(points.normals[vertex], glm::vec3(0, 0, 1));
        for (size_t extra = 0; extra < kExtraNames.size(); ++extra)
          EXPECT_EQ(points.extras[vertex * kExtraNames.size() + extra],
                    storedAs(extraType(kExtraNames[extra]),
                             valueWithExtras(vertex, kExtraNames[extra])))
              << "vertex " << vertex << " " << kExtraNames[extra];
      }
    }
  }
}

TEST(PlyReader, ignoresExtrasByDefault) {
  test::TempDir dir;
  for (const std::string format : {"ascii", "binary_little_endian"}) {
    SCOPED_TRACE(format);
    test::writeFile(dir / "e.ply", fileWithExtras(format, false).bytes());
    EXPECT_TRUE(openPointFile(dir / "e.ply")->info().extraNames.empty());
    const PointCloud points = readPointFile(dir / "e.ply");
    ASSERT_EQ(points.size(), size_t(kVerticesWithExtras));
    EXPECT_TRUE(points.extraNames.empty());
    EXPECT_TRUE(points.extras.empty());
    EXPECT_EQ(points.positions[4], glm::dvec3(4, -4, 1e6 + 4));
  }
}

TEST(PlyReader, extrasStayWithTheirPointsWhenNonFinitePointsAreDropped) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  Bytes binary;
  binary.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\n"
      "property float y\nproperty float z\nproperty float intensity\nproperty uint id\n"
      "end_header\n");
  const std::array<float, 5> xs = {1, nan, 3, nan, 5};
  for (size_t i = 0; i < xs.size(); ++i)
    binary.le(xs[i]).le(0.0f).le(0.0f).le(float(i) / 2).le(uint32_t(i * 10));
  test::TempDir dir;
  test::writeFile(dir / "b.ply", binary.bytes());
  test::writeText(dir / "a.ply",
                  "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
                  "property float z\nproperty float intensity\nproperty uint id\nend_header\n"
                  "1 0 0 0 0\nnan 0 0 0.5 10\n3 0 0 1 20\nnan 0 0 1.5 30\n5 0 0 2 40\n");
  ReadOptions options;
  options.keepExtras = true;
  for (const char* name : {"b.ply", "a.ply"}) {
    SCOPED_TRACE(name);
    ReadStats stats;
    const PointCloud points = test::readInBatches(dir / name, options, &stats, 2);
    EXPECT_EQ(stats.droppedNonFinite, 2u);
    ASSERT_EQ(points.size(), 3u);
    EXPECT_EQ(points.extras, std::vector<double>({0, 0, 1, 20, 2, 40}));
  }
}

TEST(PlyReader, carriesPropertiesOfIncompleteNormalsAndColorsAsExtras) {
  test::TempDir dir;
  test::writeText(dir / "p.ply",
                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nproperty float nx\nproperty uchar red\nend_header\n"
                  "1 2 3 4 5\n");
  ReadOptions options;
  options.keepExtras = true;
  const PointCloud points = readPointFile(dir / "p.ply", options);
  EXPECT_EQ(points.extraNames, std::vector<std::string>({"nx", "red"}));
  EXPECT_EQ(points.extras, std::vector<double>({4, 5}));
}

TEST(PlyReader, dropsAndCountsPointsWithNonFiniteCoordinates) {
  test::TempDir dir;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\n"
      "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
      "property uchar blue\nend_header\n");
  const std::array<std::array<float, 3>, 5> rows = {
      {{1, 1, 1}, {nan, 0, 0}, {2, 2, 2}, {0, -inf, 0}, {3, 3, inf}}};
  for (size_t i = 0; i < rows.size(); ++i)
    file.le(rows[i][0]).le(rows[i][1]).le(rows[i][2]).fill(3, uint8_t(i * 50));
  test::writeFile(dir / "n.ply", file.bytes());
  ReadStats stats;
  const PointCloud points = test::readInBatches(dir / "n.ply", {}, &stats, 2);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1, 1, 1));
  EXPECT_EQ(points.positions[1], glm::dvec3(2, 2, 2));
  EXPECT_NEAR(points.colors[1].r, test::linearOf8(100), 1e-6);  // colors stay with their points
  EXPECT_EQ(stats.pointsRead, 2u);
  EXPECT_EQ(stats.droppedNonFinite, 3u);

  test::writeText(dir / "n2.ply",
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
                  "property double z\nend_header\nnan 0 0\n1 inf 2\n4 5 6\n");
  readPointFile(dir / "n2.ply", {}, &stats);
  EXPECT_EQ(stats.pointsRead, 1u);
  EXPECT_EQ(stats.droppedNonFinite, 2u);
}

TEST(PlyReader, everyTruncatedPrefixOfABinaryFileThrowsFileError) {
  const std::vector<std::byte> whole = facesBeforeVertices().bytes();
  test::TempDir dir;
  test::writeFile(dir / "whole.ply", whole);
  ASSERT_EQ(readPointFile(dir / "whole.ply").size(), 3u);
  for (size_t length = 0; length < whole.size(); ++length) {
    SCOPED_TRACE("prefix of " + std::to_string(length) + " bytes");
    test::writeFile(dir / "cut.ply", {whole.begin(), whole.begin() + ptrdiff_t(length)});
    EXPECT_THROW(readPointFile(dir / "cut.ply"), FileError);
  }
}

TEST(PlyReader, truncatedBinaryVerticesReportTheOffsetAndCount) {
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n");
  const size_t headerSize = file.size();
  for (int i = 0; i < 2; ++i) file.le(1.0f).le(2.0f).le(3.0f);
  file.le(1.0f);
  test::writeFile(dir / "t.ply", file.bytes());
  try {
    readPointFile(dir / "t.ply");
    FAIL() << "no error";
  } catch (const FileError& error) {
    EXPECT_EQ(error.reason(), "file ends after 2 of 4 vertices");
    EXPECT_EQ(error.offset(), headerSize + 24);
  }
}

TEST(PlyReader, rejectsMalformedHeadersWithClearReasons) {
  const std::string xyz = "property float x\nproperty float y\nproperty float z\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"plyx\nformat ascii 1.0\nend_header\n", "does not start with 'ply'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\n" + xyz, "no end_header"},
      {"ply\nformat utf8 1.0\nelement vertex 0\n" + xyz + "end_header\n", "unknown PLY format"},
      {"ply\nformat ascii 2.0\nelement vertex 0\n" + xyz + "end_header\n",
       "unsupported PLY version"},
      {"ply\nelement vertex 0\n" + xyz + "end_header\n", "no format line"},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
       "line 3: a property before any element"},
      {"ply\nformat ascii 1.0\nelement vertex -1\n" + xyz + "end_header\n",
       "expected 'element NAME COUNT'"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
       "unknown property type 'float128'"},
      {"ply\nformat ascii 1.0\nelement f 1\nproperty list float int v\nend_header\n",
       "list count type must be an integer"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 "
       "2\n",
       "no scalar property 'z'"},
      {"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no vertex element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\n" + xyz + "texture foo\nend_header\n",
       "unknown PLY header line"},
  };
  test::TempDir dir;
  for (const auto& [text, reason] : cases) {
    SCOPED_TRACE(text);
    test::writeText(dir / "h.ply", text);
    EXPECT_NE(test::readError(dir / "h.ply").find(reason), std::string::npos)
        << test::readError(dir / "h.ply");
  }
}

TEST(PlyReader, asciiErrorsNameTheLine) {
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {header + "1 2 3\n4 5\n", "line 9: the vertex has no value for property 'z'"},
      {header + "1 2 3\n4 5 6 7\n", "line 9: more values than the 3 vertex properties"},
      {header + "1 2 3\n4 five 6\n", "line 9: property 'y' is not a number: 'five'"},
      {header + "1 2 3\n", "file ends after 1 of 3 vertices"},
  };
  test::TempDir dir;
  for (const auto& [text, reason] : cases) {
    test::writeText(dir / "a.ply", text);
    EXPECT_NE(test::readError(dir / "a.ply").find(reason), std::string::npos)
        << test::readError(dir / "a.ply");
  }
}

TEST(PlyReader, acceptsCrLfLineEndsAndBlankLines) {
  test::TempDir dir;
  test::writeText(dir / "w.ply",
                  "ply\r\nformat ascii 1.0\r\nelement vertex 2\r\nproperty float x\r\n"
                  "property float y\r\nproperty float z\r\nend_header\r\n1 2 3\r\n\r\n4 5 6\r\n");
  const PointCloud points = readPointFile(dir / "w.ply");
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[1], glm::dvec3(4, 5, 6));
}

TEST(PlyReader, hostileListLengthEndsAsTruncationNotAllocation) {
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_little_endian 1.0\nelement junk 1\n"
      "property list uint double values\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n");
  file.le<uint32_t>(0xFFFFFFFFu).le(1.0f).le(2.0f).le(3.0f);
  test::writeFile(dir / "h.ply", file.bytes());
  EXPECT_NE(test::readError(dir / "h.ply").find("file ends after 0 of 1 'junk' records"),
            std::string::npos);

  Bytes huge;
  huge.text(
      "ply\nformat binary_little_endian 1.0\nelement junk 4611686018427387904\n"
      "property double v\nelement vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n");
  test::writeFile(dir / "c.ply", huge.bytes());
  EXPECT_NE(test::readError(dir / "c.ply").find("more than any file holds"), std::string::npos);
}

}  // namespace
}  // namespace iso
