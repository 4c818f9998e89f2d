// The PLY mesh reader: vertices and faces in either order, polygons fanned into triangles, index
// and count types, indices validated, truncation and missing faces rejected.
#include "pipeline/io/ply.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

using test::Bytes;
using Triangles = std::vector<std::array<uint32_t, 3>>;

TEST(PlyMeshReader, fansAsciiPolygonsIntoTriangles) {
  test::TempDir dir;
  test::writeText(dir / "m.ply",
                  "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
                  "property float z\nproperty uchar red\nelement face 3\n"
                  "property list uchar int vertex_indices\nend_header\n"
                  "0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n0.5 0.5 1 5\n"
                  "3 0 1 4\n4 0 1 2 3\n5 4 3 2 1 0\n");
  const TriangleMesh mesh = readPlyMesh(dir / "m.ply");
  ASSERT_EQ(mesh.vertices.size(), 5u);
  EXPECT_EQ(mesh.vertices[4], glm::dvec3(0.5, 0.5, 1));
  EXPECT_EQ(mesh.triangles,
            (Triangles{{0, 1, 4}, {0, 1, 2}, {0, 2, 3}, {4, 3, 2}, {4, 2, 1}, {4, 1, 0}}));
}

TEST(PlyMeshReader, readsFacesBeforeVerticesWithOtherCountAndIndexTypes) {
  test::TempDir dir;
  Bytes file;
  file.text(
      "ply\nformat binary_big_endian 1.0\nelement face 2\nproperty uchar flags\n"
      "property list uint uint vertex_index\nproperty list int8 float texcoord\n"
      "element vertex 4\nproperty double z\nproperty double y\nproperty double x\n"
      "end_header\n");
  file.be<uint8_t>(1).be<uint32_t>(3).be<uint32_t>(0).be<uint32_t>(1).be<uint32_t>(2);
  file.be<int8_t>(2).be(0.5f).be(0.5f);
  file.be<uint8_t>(1).be<uint32_t>(4).be<uint32_t>(3).be<uint32_t>(2).be<uint32_t>(1).be<uint32_t>(
      0);
  file.be<int8_t>(0);
  for (int i = 0; i < 4; ++i) file.be(double(i)).be(double(-i)).be(100.0 + i);
  test::writeFile(dir / "m.ply", file.bytes());
  const TriangleMesh mesh = readPlyMesh(dir / "m.ply");
  ASSERT_EQ(mesh.vertices.size(), 4u);
  EXPECT_EQ(mesh.vertices[3], glm::dvec3(103, -3, 3));
  EXPECT_EQ(mesh.triangles, (Triangles{{0, 1, 2}, {3, 2, 1}, {3, 1, 0}}));
}

TEST(PlyMeshReader, keepsNonFiniteVerticesSoIndicesStayValid) {
  test::TempDir dir;
  test::writeText(dir / "m.ply",
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                  "end_header\nnan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  const TriangleMesh mesh = readPlyMesh(dir / "m.ply");
  EXPECT_EQ(mesh.vertices.size(), 3u);
  EXPECT_EQ(mesh.triangles.size(), 1u);
}

std::string meshError(const std::filesystem::path& path) {
  try {
    readPlyMesh(path);
  } catch (const FileError& error) {
    return error.what();
  }
  return "";
}

TEST(PlyMeshReader, rejectsIndicesOutsideTheVertices) {
  test::TempDir dir;
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n";
  test::writeText(dir / "a.ply", header + "3 0 1 3\n");
  EXPECT_NE(meshError(dir / "a.ply").find("line 13: a face refers to vertex 3, but there are 3"),
            std::string::npos)
      << meshError(dir / "a.ply");
  test::writeText(dir / "n.ply", header + "3 0 -1 2\n");
  EXPECT_NE(meshError(dir / "n.ply").find("vertex -1"), std::string::npos);

  Bytes binary;
  binary.text(
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uchar uint vertex_indices\nend_header\n");
  binary.le(0.0f).le(0.0f).le(0.0f).le<uint8_t>(3).le<uint32_t>(0).le<uint32_t>(0xFFFFFFFFu);
  test::writeFile(dir / "b.ply", binary.bytes());
  try {
    readPlyMesh(dir / "b.ply");
    FAIL() << "no error";
  } catch (const FileError& error) {
    EXPECT_EQ(error.offset(), binary.size() - 4);
    EXPECT_NE(error.reason().find("vertex 4294967295"), std::string::npos);
  }
}

TEST(PlyMeshReader, rejectsFilesWithoutFacesOrIndexLists) {
  test::TempDir dir;
  test::writeText(dir / "p.ply",
                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nend_header\n0 0 0\n");
  EXPECT_NE(meshError(dir / "p.ply").find("no faces"), std::string::npos);
  test::writeText(dir / "f.ply",
                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty list uchar float vertex_indices\n"
                  "end_header\n0 0 0\n3 0 0 0\n");
  EXPECT_NE(meshError(dir / "f.ply").find("integer type"), std::string::npos);
  test::writeText(dir / "s.ply",
                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty int vertex_indices\n"
                  "end_header\n0 0 0\n3\n");
  EXPECT_NE(meshError(dir / "s.ply").find("no list property vertex_indices"), std::string::npos);
}

TEST(PlyMeshReader, everyTruncatedPrefixOfABinaryMeshThrowsFileError) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 1}};
  mesh.triangles = {{0, 1, 2}, {1, 3, 2}};
  test::TempDir dir;
  writePlyMesh(dir / "whole.ply", mesh);
  const std::vector<std::byte> whole = test::readFile(dir / "whole.ply");
  ASSERT_EQ(readPlyMesh(dir / "whole.ply").triangles, mesh.triangles);
  for (size_t length = 0; length < whole.size(); ++length) {
    SCOPED_TRACE("prefix of " + std::to_string(length) + " bytes");
    test::writeFile(dir / "cut.ply", {whole.begin(), whole.begin() + ptrdiff_t(length)});
    EXPECT_THROW(readPlyMesh(dir / "cut.ply"), FileError);
  }
}

TEST(PlyMeshReader, readsGzipCompressedAsciiMeshes) {
  test::TempDir dir;
  test::writeGzip(dir / "m.ply.gz",
                  Bytes()
                      .text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                            "property float y\nproperty float z\nelement face 1\n"
                            "property list uchar int vertex_indices\nend_header\n"
                            "0 0 0\n1 0 0\n0 1 0\n3 2 1 0\n")
                      .bytes());
  const TriangleMesh mesh = readPlyMesh(dir / "m.ply.gz");
  EXPECT_EQ(mesh.vertices.size(), 3u);
  EXPECT_EQ(mesh.triangles, (Triangles{{2, 1, 0}}));
}

}  // namespace
}  // namespace iso
