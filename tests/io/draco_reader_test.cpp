// The Draco reader on files encoded here with libdraco's own encoder: point clouds with and without
// quantization, normals and 8-bit, 16-bit and float colors, integer positions, meshes read as
// points, batches, non-finite points, and truncated, corrupt and empty files.
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <draco/point_cloud/point_cloud_builder.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "pipeline/io/color.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

struct DracoPoints {
  std::vector<std::array<float, 3>> positions;
  std::vector<std::array<float, 3>> normals;   // empty: no NORMAL attribute
  std::vector<std::array<uint8_t, 3>> colors;  // empty: no COLOR attribute
};

// Points on a grid 1 apart (x from 0 to 9, y and z growing slowly), each with its own normal and
// color, so that a decoded point can be matched to its original by position.
DracoPoints gridPoints(int count) {
  DracoPoints points;
  for (int i = 0; i < count; ++i) {
    const float x = float(i % 10), y = float(i / 10 % 10), z = float(i / 100);
    points.positions.push_back({x + 0.125f, y - 0.375f, z * 1.5f});
    const float length = std::sqrt(1.0f + x * x + y * y);
    points.normals.push_back({x / length, y / length, 1.0f / length});
    points.colors.push_back({uint8_t(i % 256), uint8_t(255 - i % 256), uint8_t(i * 7 % 256)});
  }
  return points;
}

std::unique_ptr<draco::PointCloud> buildCloud(const DracoPoints& points) {
  draco::PointCloudBuilder builder;
  const auto count = static_cast<uint32_t>(points.positions.size());
  builder.Start(count);
  const int position =
      builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  builder.SetAttributeValuesForAllPoints(position, points.positions.data(), 0);
  if (!points.normals.empty()) {
    const int normal = builder.AddAttribute(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32);
    builder.SetAttributeValuesForAllPoints(normal, points.normals.data(), 0);
  }
  if (!points.colors.empty()) {
    const int color = builder.AddAttribute(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8);
    builder.SetAttributeValuesForAllPoints(color, points.colors.data(), 0);
  }
  return builder.Finalize(false);
}

struct EncodeOptions {
  int positionBits = 0;  // 0: positions stored losslessly
  int normalBits = 0;
  // Sequential encoding keeps the points' order; the k-d tree (quantized positions only) does not.
  bool keepOrder = true;
};

std::vector<std::byte> toBytes(const draco::EncoderBuffer& buffer) {
  const auto* data = reinterpret_cast<const std::byte*>(buffer.data());
  return {data, data + buffer.size()};
}

std::vector<std::byte> encode(const draco::PointCloud& cloud, const EncodeOptions& options) {
  draco::Encoder encoder;
  if (options.positionBits > 0)
    encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, options.positionBits);
  if (options.normalBits > 0)
    encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, options.normalBits);
  encoder.SetEncodingMethod(options.keepOrder ? draco::POINT_CLOUD_SEQUENTIAL_ENCODING
                                              : draco::POINT_CLOUD_KD_TREE_ENCODING);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodePointCloudToBuffer(cloud, &buffer);
  EXPECT_TRUE(status.ok()) << status.error_msg_string();
  return toBytes(buffer);
}

void writeDraco(const std::filesystem::path& path, const DracoPoints& points,
                const EncodeOptions& options = {}) {
  test::writeFile(path, encode(*buildCloud(points), options));
}

// The index of the original point nearest to p (brute force).
size_t nearestOriginal(const DracoPoints& points, const glm::dvec3& p) {
  size_t best = 0;
  double bestDistance = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < points.positions.size(); ++i) {
    const auto& q = points.positions[i];
    const double distance = glm::length(p - glm::dvec3(q[0], q[1], q[2]));
    if (distance < bestDistance) {
      bestDistance = distance;
      best = i;
    }
  }
  return best;
}

TEST(DracoReader, readsUnquantizedPositionsNormalsAndColorsExactly) {
  const DracoPoints original = gridPoints(1000);
  test::TempDir dir;
  writeDraco(dir / "a.drc", original);
  const auto reader = openPointFile(dir / "a.drc");
  EXPECT_EQ(reader->info().format, "draco");
  EXPECT_EQ(reader->info().declaredPoints, 1000u);
  EXPECT_TRUE(reader->info().hasNormals);
  EXPECT_TRUE(reader->info().hasColors);
  ReadStats stats;
  const PointCloud points = test::readInBatches(dir / "a.drc", {}, &stats, 64);
  ASSERT_EQ(points.size(), 1000u);
  EXPECT_EQ(stats.pointsRead, 1000u);
  EXPECT_EQ(stats.droppedNonFinite, 0u);
  for (size_t i = 0; i < points.size(); ++i) {
    SCOPED_TRACE("point " + std::to_string(i));
    const auto& p = original.positions[i];
    const auto& n = original.normals[i];
    const auto& c = original.colors[i];
    ASSERT_EQ(points.positions[i], glm::dvec3(p[0], p[1], p[2]));
    ASSERT_EQ(points.normals[i], glm::vec3(n[0], n[1], n[2]));
    ASSERT_NEAR(points.colors[i].r, test::linearOf8(c[0]), 1e-6);
    ASSERT_NEAR(points.colors[i].g, test::linearOf8(c[1]), 1e-6);
    ASSERT_NEAR(points.colors[i].b, test::linearOf8(c[2]), 1e-6);
  }
}

TEST(DracoReader, quantizedPositionsLieWithinTheQuantizationStep) {
  const DracoPoints original = gridPoints(1000);
  test::TempDir dir;
  constexpr int kBits = 11;
  writeDraco(dir / "q.drc", original, {.positionBits = kBits, .normalBits = 8, .keepOrder = false});
  const PointCloud points = test::readInBatches(dir / "q.drc", {}, nullptr, 100);
  ASSERT_EQ(points.size(), 1000u);
  // Draco quantizes every axis over the largest extent of the bounding box (here z: 13.5).
  const double step = 13.5 / double((1 << kBits) - 1);
  std::vector<int> matches(original.positions.size(), 0);
  for (size_t i = 0; i < points.size(); ++i) {
    SCOPED_TRACE("point " + std::to_string(i));
    const size_t j = nearestOriginal(original, points.positions[i]);
    ++matches[j];
    const auto& p = original.positions[j];
    for (int axis = 0; axis < 3; ++axis) ASSERT_NEAR(points.positions[i][axis], p[axis], step);
    const auto& n = original.normals[j];
    EXPECT_GT(glm::dot(points.normals[i], glm::vec3(n[0], n[1], n[2])), 0.99f);
    ASSERT_NEAR(points.colors[i].r, test::linearOf8(original.colors[j][0]), 1e-6);
  }
  EXPECT_EQ(std::count(matches.begin(), matches.end(), 1), 1000);  // each original exactly once
}

TEST(DracoReader, readsPointsWithoutOptionalAttributes) {
  DracoPoints original = gridPoints(20);
  original.normals.clear();
  original.colors.clear();
  test::TempDir dir;
  writeDraco(dir / "p.drc", original);
  const auto reader = openPointFile(dir / "p.drc");
  EXPECT_FALSE(reader->info().hasNormals);
  EXPECT_FALSE(reader->info().hasColors);
  const PointCloud points = readPointFile(dir / "p.drc");
  ASSERT_EQ(points.size(), 20u);
  EXPECT_EQ(points.positions[13], glm::dvec3(3.125, 0.625, 0.0));
}

// A cloud of `count` points with POSITION of type T (values 1, 2, 3 + i) and a COLOR attribute of
// type C with `components` components, every point colored `color`.
template <typename T, typename C>
std::unique_ptr<draco::PointCloud> typedCloud(draco::DataType positionType,
                                              draco::DataType colorType, int components,
                                              std::array<C, 4> color) {
  draco::PointCloudBuilder builder;
  builder.Start(4);
  const int position = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, positionType);
  const int rgb =
      builder.AddAttribute(draco::GeometryAttribute::COLOR, int8_t(components), colorType);
  for (uint32_t i = 0; i < 4; ++i) {
    const std::array<T, 3> p = {T(1), T(2), T(3 + i)};
    builder.SetAttributeValueForPoint(position, draco::PointIndex(i), p.data());
    builder.SetAttributeValueForPoint(rgb, draco::PointIndex(i), color.data());
  }
  return builder.Finalize(false);
}

TEST(DracoReader, readsIntegerPositionsAndSixteenBitAndFloatColors) {
  test::TempDir dir;
  test::writeFile(dir / "u16.drc",
                  encode(*typedCloud<int16_t, uint16_t>(draco::DT_INT16, draco::DT_UINT16, 3,
                                                        {65535, 0, 32768, 0}),
                         {}));
  PointCloud points = test::readInBatches(dir / "u16.drc", {}, nullptr, 3);
  ASSERT_EQ(points.size(), 4u);
  EXPECT_EQ(points.positions[3], glm::dvec3(1, 2, 6));
  EXPECT_FLOAT_EQ(points.colors[0].r, 1.0f);
  EXPECT_FLOAT_EQ(points.colors[0].g, 0.0f);
  EXPECT_NEAR(points.colors[0].b, srgbToLinear(32768.0f / 65535.0f), 1e-6);

  // RGBA: the alpha channel is ignored.
  test::writeFile(dir / "f.drc",
                  encode(*typedCloud<uint32_t, float>(draco::DT_UINT32, draco::DT_FLOAT32, 4,
                                                      {0.5f, 1.5f, -0.5f, 0.25f}),
                         {}));
  points = readPointFile(dir / "f.drc");
  ASSERT_EQ(points.size(), 4u);
  EXPECT_EQ(points.positions[0], glm::dvec3(1, 2, 3));
  EXPECT_NEAR(points.colors[2].r, srgbToLinear(0.5f), 1e-6);
  EXPECT_FLOAT_EQ(points.colors[2].g, 1.0f);  // clamped
  EXPECT_FLOAT_EQ(points.colors[2].b, 0.0f);
}

TEST(DracoReader, readsTheVerticesOfAMeshAsPoints) {
  // A square pyramid: 5 vertices, 6 triangles (4 sides and the base split in two).
  const std::array<std::array<float, 3>, 5> vertices = {
      {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 3}}};
  const std::array<std::array<int, 3>, 6> faces = {
      {{0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}, {0, 2, 1}, {0, 3, 2}}};
  draco::TriangleSoupMeshBuilder builder;
  builder.Start(int(faces.size()));
  const int position =
      builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  for (size_t f = 0; f < faces.size(); ++f)
    builder.SetAttributeValuesForFace(position, draco::FaceIndex(uint32_t(f)),
                                      vertices[faces[f][0]].data(), vertices[faces[f][1]].data(),
                                      vertices[faces[f][2]].data());
  const std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  ASSERT_NE(mesh, nullptr);
  draco::Encoder encoder;
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, 12);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(encoder.EncodeMeshToBuffer(*mesh, &buffer).ok());
  test::TempDir dir;
  test::writeFile(dir / "m.drc", toBytes(buffer));

  const PointCloud points = readPointFile(dir / "m.drc");
  ASSERT_EQ(points.size(), vertices.size());  // corners shared by faces are one point
  const double step = 3.0 / double((1 << 12) - 1);
  std::vector<int> found(vertices.size(), 0);
  for (const glm::dvec3& p : points.positions)
    for (size_t v = 0; v < vertices.size(); ++v)
      if (glm::length(p - glm::dvec3(vertices[v][0], vertices[v][1], vertices[v][2])) < step)
        ++found[v];
  EXPECT_EQ(found, std::vector<int>(vertices.size(), 1));
}

TEST(DracoReader, readsGzipCompressedFiles) {
  const DracoPoints original = gridPoints(300);
  test::TempDir dir;
  test::writeGzip(dir / "a.drc.gz", encode(*buildCloud(original), {}));
  const PointCloud points = readPointFile(dir / "a.drc.gz");
  ASSERT_EQ(points.size(), 300u);
  EXPECT_EQ(points.positions[299], glm::dvec3(9.125, 8.625, 3.0));
}

TEST(DracoReader, dropsAndCountsPointsWithNonFiniteCoordinates) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  DracoPoints original = gridPoints(5);
  original.positions[1][0] = nan;
  original.positions[3][1] = -inf;
  original.positions[4][2] = inf;
  test::TempDir dir;
  writeDraco(dir / "n.drc", original);
  ReadStats stats;
  const PointCloud points = test::readInBatches(dir / "n.drc", {}, &stats, 2);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points.positions[1], glm::dvec3(2.125, -0.375, 0.0));
  EXPECT_NEAR(points.colors[1].r, test::linearOf8(2), 1e-6);  // colors stay with their points
  EXPECT_EQ(stats.pointsRead, 2u);
  EXPECT_EQ(stats.droppedNonFinite, 3u);
}

TEST(DracoReader, rejectsAFileWithoutPositions) {
  draco::PointCloudBuilder builder;
  builder.Start(2);
  const int generic = builder.AddAttribute(draco::GeometryAttribute::GENERIC, 3, draco::DT_FLOAT32);
  const std::array<float, 6> values = {1, 2, 3, 4, 5, 6};
  builder.SetAttributeValuesForAllPoints(generic, values.data(), 0);
  test::TempDir dir;
  test::writeFile(dir / "g.drc", encode(*builder.Finalize(false), {}));
  const std::string error = test::readError(dir / "g.drc");
  EXPECT_NE(error.find("g.drc"), std::string::npos) << error;
  EXPECT_NE(error.find("the Draco file has no POSITION attribute"), std::string::npos) << error;
}

TEST(DracoReader, everyTruncatedPrefixThrowsFileErrorNamingTheFile) {
  test::TempDir dir;
  for (const bool quantized : {false, true}) {
    SCOPED_TRACE(quantized ? "quantized" : "lossless");
    const std::vector<std::byte> whole =
        encode(*buildCloud(gridPoints(50)), {.positionBits = quantized ? 14 : 0,
                                             .normalBits = quantized ? 10 : 0,
                                             .keepOrder = !quantized});
    for (size_t length = 0; length < whole.size(); ++length) {
      SCOPED_TRACE("prefix of " + std::to_string(length) + " bytes");
      test::writeFile(dir / "cut.drc", {whole.begin(), whole.begin() + ptrdiff_t(length)});
      const std::string error = test::readError(dir / "cut.drc");
      EXPECT_NE(error.find("cut.drc"), std::string::npos) << error;
    }
  }
}

TEST(DracoReader, rejectsCorruptAndEmptyFilesWithClearReasons) {
  test::TempDir dir;
  test::writeText(dir / "empty.drc", "");
  EXPECT_NE(test::readError(dir / "empty.drc").find("empty.drc: byte 0: not a Draco file"),
            std::string::npos)
      << test::readError(dir / "empty.drc");

  test::writeText(dir / "magic.drc", "DRACO");
  EXPECT_NE(
      test::readError(dir / "magic.drc")
          .find("magic.drc: byte 0: Draco cannot decode the file: Failed to parse Draco header"),
      std::string::npos)
      << test::readError(dir / "magic.drc");

  // A version from the future (bytes 5 and 6 of the header are the major and minor version).
  std::vector<std::byte> bytes = encode(*buildCloud(gridPoints(10)), {});
  bytes[5] = std::byte{99};
  test::writeFile(dir / "future.drc", bytes);
  const std::string error = test::readError(dir / "future.drc");
  EXPECT_NE(error.find("future.drc"), std::string::npos) << error;
  EXPECT_NE(error.find("Draco cannot decode the file: "), std::string::npos) << error;
  EXPECT_NE(error.find("version"), std::string::npos) << error;
}

TEST(DracoReader, refusesPointCountsTheFileCannotHold) {
  // A point cloud's count is the int32 after the 11-byte header (Draco bitstream spec, "Header");
  // Draco would size every attribute by it before noticing that the values are missing.
  constexpr size_t kCountAt = 11;
  std::vector<std::byte> bytes = encode(*buildCloud(gridPoints(10)), {});
  ASSERT_EQ(std::to_integer<int>(bytes[kCountAt]), 10);
  test::TempDir dir;
  const std::vector<std::pair<uint32_t, std::string>> cases = {
      {0x7FFFFFFFu, "byte 11: the file declares 2147483647 points in "},
      {0xFFFFFFFFu, "byte 11: negative point count -1"}};
  for (const auto& [count, reason] : cases) {
    for (size_t i = 0; i < 4; ++i) bytes[kCountAt + i] = std::byte((count >> (8 * i)) & 0xFF);
    test::writeFile(dir / "c.drc", bytes);
    const std::string error = test::readError(dir / "c.drc");
    EXPECT_NE(error.find("c.drc: " + reason), std::string::npos) << error;
  }
}

TEST(DracoReader, survivesCorruptedBytesEverywhere) {
  // Corruption past the header may decode to other points (Draco has no checksum); it must never
  // crash or throw anything but FileError.
  const std::vector<std::byte> whole = encode(
      *buildCloud(gridPoints(50)), {.positionBits = 12, .normalBits = 8, .keepOrder = false});
  test::TempDir dir;
  for (size_t at = 0; at < whole.size(); ++at) {
    SCOPED_TRACE("byte " + std::to_string(at));
    std::vector<std::byte> bytes = whole;
    bytes[at] ^= std::byte{0x5A};
    test::writeFile(dir / "x.drc", bytes);
    try {
      test::readInBatches(dir / "x.drc");
    } catch (const FileError&) {
    }
  }
}

}  // namespace
}  // namespace iso
