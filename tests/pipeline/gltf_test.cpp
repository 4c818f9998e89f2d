// The glTF binary export and the simplified meshes: the file decodes (meshoptimizer's decoders) to
// the uncompressed file's streams, and those to the mesh within half a quantization step; the
// simplified mesh stays within its error of the analytic sphere and keeps open borders.
#include <gtest/gtest.h>
#include <meshoptimizer.h>
#include <tbb/global_control.h>

#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <glm/geometric.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>

#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/export.h"
#include "pipeline/analysis/gltf.h"
#include "pipeline/analysis/tiles.h"
#include "pipeline/geom/shape.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

uint32_t word(const std::vector<uint8_t>& b, size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

struct Glb {
  nlohmann::json json;
  std::vector<uint8_t> bin;
};

// The two chunks of a .glb file, its header and chunk types checked.
Glb parseGlb(const std::vector<uint8_t>& bytes) {
  EXPECT_GE(bytes.size(), 28u);
  EXPECT_EQ(word(bytes, 0), 0x46546C67u);  // "glTF"
  EXPECT_EQ(word(bytes, 4), 2u);
  EXPECT_EQ(word(bytes, 8), bytes.size());
  const uint32_t jsonLength = word(bytes, 12);
  EXPECT_EQ(word(bytes, 16), 0x4E4F534Au);  // "JSON"
  EXPECT_EQ(jsonLength % 4, 0u);
  Glb glb;
  glb.json = nlohmann::json::parse(bytes.begin() + 20, bytes.begin() + 20 + jsonLength);
  const size_t at = 20 + jsonLength;
  const uint32_t binLength = word(bytes, at);
  EXPECT_EQ(word(bytes, at + 4), 0x004E4942u);  // "BIN"
  EXPECT_EQ(at + 8 + binLength, bytes.size());
  glb.bin.assign(bytes.begin() + long(at) + 8, bytes.end());
  return glb;
}

// The uncompressed bytes of a buffer view: decoded by meshoptimizer when compressed.
std::vector<uint8_t> viewBytes(const Glb& glb, size_t view) {
  const nlohmann::json& v = glb.json["bufferViews"][view];
  std::vector<uint8_t> out(v["byteLength"].get<size_t>());
  if (!v.contains("extensions")) {
    const size_t offset = v["byteOffset"].get<size_t>();
    std::memcpy(out.data(), glb.bin.data() + offset, out.size());
    return out;
  }
  const nlohmann::json& c = v["extensions"]["EXT_meshopt_compression"];
  const uint8_t* source = glb.bin.data() + c["byteOffset"].get<size_t>();
  const size_t length = c["byteLength"].get<size_t>(), count = c["count"].get<size_t>(),
               stride = c["byteStride"].get<size_t>();
  int result = -1;
  if (c["mode"] == "ATTRIBUTES") {
    result = meshopt_decodeVertexBuffer(out.data(), count, stride, source, length);
    if (c.value("filter", "NONE") == "OCTAHEDRAL")
      meshopt_decodeFilterOct(out.data(), count, stride);
  } else if (c["mode"] == "TRIANGLES")
    result = meshopt_decodeIndexBuffer(out.data(), count, stride, source, length);
  EXPECT_EQ(result, 0) << c.dump();
  return out;
}

test::Converted coloredSphere(const std::filesystem::path& path) {
  PointCloud scan = test::scanOf("sphere", 30000);
  for (const glm::dvec3& p : scan.positions)  // a color that varies smoothly over the sphere
    scan.colors.push_back(glm::vec3(0.5 + 0.4 * p.x, 0.5 + 0.4 * p.y, 0.5 + 0.4 * p.z));
  return test::convertAndLoad(scan, path);
}

TEST(GlbExport, decodesToTheMeshWithinHalfAStepAndToTheSameStreamsAsUncompressed) {
  test::TempDir dir;
  const test::Converted c = coloredSphere(dir / "s.iso");
  std::vector<uint32_t> leaves;
  TriangleMesh mesh = extractMesh(c.surface, nullptr, &leaves);
  MeshAttributes attributes = meshAttributes(c.surface, mesh, leaves);
  ASSERT_EQ(attributes.normals.size(), mesh.vertices.size());
  ASSERT_EQ(attributes.colors.size(), mesh.vertices.size());
  optimizeMeshOrder(mesh, attributes);
  GlbStats stats;
  const Glb packed = parseGlb(encodeGlb(mesh, attributes, {}, &stats));
  const Glb plain = parseGlb(encodeGlb(mesh, attributes, {.compress = false}));
  ASSERT_TRUE(stats.quantized);
  EXPECT_EQ(packed.json["extensionsRequired"],
            nlohmann::json({"KHR_mesh_quantization", "EXT_meshopt_compression"}));
  // The compressed vertex streams are the uncompressed ones (the index codec may rotate a
  // triangle's vertices: compared below).
  ASSERT_EQ(packed.json["bufferViews"].size(), 4u);  // positions, normals, colors, indices
  for (size_t v = 0; v < 3; ++v) EXPECT_TRUE(viewBytes(packed, v) == viewBytes(plain, v)) << v;
  EXPECT_LT(packed.bin.size(), plain.bin.size() / 2);
  std::printf("%zu vertices, %zu triangles: %zu bytes compressed, %zu not\n", mesh.vertices.size(),
              mesh.triangles.size(), packed.bin.size(), plain.bin.size());

  // Positions: translation + scale · q, within half a step of the mesh's (every axis).
  const nlohmann::json& node = packed.json["nodes"][0];
  const glm::dvec3 t(node["translation"][0], node["translation"][1], node["translation"][2]);
  const double step = node["scale"][0].get<double>();
  EXPECT_DOUBLE_EQ(step, stats.positionStep);
  const std::vector<uint8_t> positions = viewBytes(packed, 0), normals = viewBytes(packed, 1),
                             colors = viewBytes(packed, 2), indices = viewBytes(packed, 3);
  double worst = 0.0, worstAngle = 0.0, worstColor = 0.0;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    uint16_t q[3];
    std::memcpy(q, positions.data() + 8 * i, 6);
    for (int a = 0; a < 3; ++a)
      worst = std::max(worst, std::abs(t[a] + step * q[a] - mesh.vertices[i][a]));
    const glm::dvec3 n(int8_t(normals[4 * i]) / 127.0, int8_t(normals[4 * i + 1]) / 127.0,
                       int8_t(normals[4 * i + 2]) / 127.0);
    const double cosine =
        glm::dot(glm::normalize(n), glm::normalize(glm::dvec3(attributes.normals[i])));
    worstAngle = std::max(worstAngle, std::acos(std::min(1.0, cosine)));
    // The surface's color is the points' (a smooth function of the position) near the vertex.
    const glm::dvec3 p = mesh.vertices[i];
    for (int a = 0; a < 3; ++a)
      worstColor = std::max(worstColor, std::abs(colors[4 * i + size_t(a)] / 255.0 -
                                                 (0.5 + 0.4 * p[a] / glm::length(p))));
  }
  EXPECT_LE(worst, 0.5 * step * (1 + 1e-9));
  std::printf("largest normal error %.3f degrees\n", worstAngle * 180 / M_PI);
  EXPECT_LT(worstAngle, 1.5 * M_PI / 180);  // 8-bit octahedral, decoded to bytes: about a degree
  EXPECT_LT(worstColor, 0.02);
  // The normals point out of the sphere.
  for (size_t i = 0; i < mesh.vertices.size(); ++i)
    ASSERT_GT(glm::dot(glm::dvec3(attributes.normals[i]), mesh.vertices[i]), 0.9);
  // The mesh's triangles in its order, each maybe rotated (the same facing); 4-byte indices past
  // 65,535 vertices. The uncompressed file has them as they are.
  const bool wide = mesh.vertices.size() > 65535;
  ASSERT_EQ(indices.size(), mesh.triangles.size() * 3 * (wide ? 4 : 2));
  const auto indexAt = [&](const std::vector<uint8_t>& bytes, size_t i) {
    uint32_t index = 0;
    std::memcpy(&index, bytes.data() + (wide ? 4 : 2) * i, wide ? 4 : 2);
    return index;
  };
  const std::vector<uint8_t> plainIndices = viewBytes(plain, 3);
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const std::array<uint32_t, 3> got = {indexAt(indices, 3 * t), indexAt(indices, 3 * t + 1),
                                         indexAt(indices, 3 * t + 2)};
    const auto& want = mesh.triangles[t];
    bool same = false;
    for (size_t r = 0; r < 3; ++r)
      same =
          same || (got[r] == want[0] && got[(r + 1) % 3] == want[1] && got[(r + 2) % 3] == want[2]);
    ASSERT_TRUE(same) << t;
    for (size_t c = 0; c < 3; ++c) ASSERT_EQ(indexAt(plainIndices, 3 * t + c), want[c]);
  }
  // Positions the 16-bit step would blur are written as float.
  GlbStats fine;
  const Glb floats = parseGlb(encodeGlb(mesh, attributes, {.maxPositionStep = step / 2}, &fine));
  EXPECT_FALSE(fine.quantized);
  EXPECT_EQ(floats.json["accessors"][0]["componentType"], 5126);
  const std::vector<uint8_t> exact = viewBytes(floats, 0);
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    float f[3];
    std::memcpy(f, exact.data() + 12 * i, 12);
    const nlohmann::json& fn = floats.json["nodes"][0];
    for (int a = 0; a < 3; ++a)
      ASSERT_NEAR(fn["translation"][a].get<double>() + f[a], mesh.vertices[i][a], 1e-6);
  }
}

// The vertices on edges used by one triangle.
std::set<std::tuple<double, double, double>> borderVertices(const TriangleMesh& mesh) {
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  for (const auto& t : mesh.triangles)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[size_t(e)], b = t[size_t((e + 1) % 3)];
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  std::set<std::tuple<double, double, double>> out;
  for (const auto& [edge, count] : uses)
    if (count == 1)
      for (uint32_t v : {edge.first, edge.second})
        out.insert({mesh.vertices[v].x, mesh.vertices[v].y, mesh.vertices[v].z});
  return out;
}

// A sphere of one color baked under a distant point light: the glTF's COLOR_0 is the lit color
// (the material's diffuse weight × the color × cos θ) and its material is unlit.
TEST(GlbExport, aBakedFilesColorsAreLitAndItsMaterialUnlit) {
  test::TempDir dir;
  PointCloud scan = test::scanOf("sphere", 30000);
  scan.colors.assign(scan.size(), glm::vec3(0.5f, 0.6f, 0.7f));
  BuildOptions options;
  BakeLight light;
  light.position = {0.0, 0.0, 10.0};
  options.lighting.enabled = true;
  options.lighting.lights = {light};
  options.lighting.bounces = 0;
  options.lighting.diffuse = 0.8f;
  const test::Converted c = test::convertAndLoad(scan, dir / "lit.iso", options);
  ASSERT_TRUE(c.surface.hasIrradiance());
  const Reader reader = Reader::open(dir / "lit.iso");
  const std::optional<BakedAppearance> baked = bakedAppearance(reader);
  ASSERT_TRUE(baked.has_value());
  EXPECT_FLOAT_EQ(baked->diffuse, 0.8f);
  std::vector<uint32_t> leaves;
  TriangleMesh mesh = extractMesh(c.surface, nullptr, &leaves);
  MeshAttributes attributes = meshAttributes(c.surface, mesh, leaves, &*baked);
  ASSERT_EQ(attributes.colors.size(), mesh.vertices.size());
  double worst = 0.0;
  size_t checked = 0;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const glm::dvec3 p = mesh.vertices[i], n = glm::normalize(p);
    const double cosine = glm::dot(n, glm::normalize(glm::dvec3(0.0, 0.0, 10.0) - p));
    // The terminator: the light is interpolated across the leaves there.
    if (std::abs(cosine) < 0.1) continue;
    const glm::dvec3 want = 0.8 * std::max(cosine, 0.0) * glm::dvec3(0.5, 0.6, 0.7);
    for (int a = 0; a < 3; ++a)
      worst = std::max(worst, std::abs(double(attributes.colors[i][a]) - want[a]));
    ++checked;
  }
  std::printf("baked sphere: %zu vertices, largest color error %.4f\n", checked, worst);
  EXPECT_GT(checked, mesh.vertices.size() / 2);
  EXPECT_LT(worst, 0.01);
  const Glb glb = parseGlb(encodeGlb(mesh, attributes, {.unlit = true}));
  EXPECT_NE(std::find(glb.json["extensionsUsed"].begin(), glb.json["extensionsUsed"].end(),
                      "KHR_materials_unlit"),
            glb.json["extensionsUsed"].end());
  EXPECT_EQ(std::find(glb.json["extensionsRequired"].begin(),
                      glb.json["extensionsRequired"].end(), "KHR_materials_unlit"),
            glb.json["extensionsRequired"].end());
  EXPECT_TRUE(glb.json["materials"][0]["extensions"].contains("KHR_materials_unlit"));
  for (const nlohmann::json& primitive : glb.json["meshes"][0]["primitives"])
    EXPECT_EQ(primitive["material"], 0);
  EXPECT_TRUE(glb.json["meshes"][0]["primitives"][0]["attributes"].contains("COLOR_0"));
}

// An open surface shows its inside where it ends: every primitive (the surface and the skirts)
// has the one material, double-sided, lit by default or unlit for baked colors, so that a viewer
// culls no face of it.
TEST(GlbExport, everyPrimitiveIsDrawnDoubleSidedLitOrUnlit) {
  // Two triangles of a square, open all around; the second counts as a skirt.
  TriangleMesh square;
  square.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  square.triangles = {{0, 1, 2}, {0, 2, 3}};
  MeshAttributes attributes;
  for (const bool unlit : {false, true}) {
    SCOPED_TRACE(unlit ? "unlit" : "lit");
    const Glb glb = parseGlb(encodeGlb(square, attributes, {.skirtsFrom = 1, .unlit = unlit}));
    ASSERT_EQ(glb.json["materials"].size(), 1u);
    const nlohmann::json& material = glb.json["materials"][0];
    EXPECT_EQ(material["doubleSided"], true);
    EXPECT_EQ(material.contains("extensions"), unlit);
    if (!unlit) {
      EXPECT_EQ(material, nlohmann::json({{"doubleSided", true}}));
    }
    const nlohmann::json& primitives = glb.json["meshes"][0]["primitives"];
    ASSERT_EQ(primitives.size(), 2u);
    for (const nlohmann::json& primitive : primitives) EXPECT_EQ(primitive["material"], 0);
  }
}

TEST(MeshSimplification, staysWithinItsErrorOfTheSphereAndKeepsOpenBorders) {
  test::TempDir dir;
  const test::Converted sphere = test::convertAndLoad(test::scanOf("sphere", 30000), dir / "s.iso");
  TriangleMesh mesh = extractMesh(sphere.surface);
  double original = 0.0;
  for (const glm::dvec3& v : mesh.vertices)
    original = std::max(original, std::abs(glm::length(v) - 1));
  const size_t before = mesh.triangles.size();
  for (const double limit : {0.002, 0.01}) {
    TriangleMesh simplified = mesh;
    MeshAttributes none;
    const double measured = simplifyMesh(simplified, none, limit);
    EXPECT_LE(measured, limit);
    EXPECT_GT(measured, 0.3 * limit);  // simplified about as far as allowed
    EXPECT_LT(simplified.triangles.size(), before / 4) << limit;
    // Every point of every triangle (a 5×5 barycentric grid) within the limit of the unit sphere,
    // beside the error the unsimplified mesh had.
    double worst = 0.0;
    for (const auto& t : simplified.triangles)
      for (int i = 0; i <= 4; ++i)
        for (int j = 0; i + j <= 4; ++j) {
          const glm::dvec3 p =
              (double(i) * simplified.vertices[t[0]] + double(j) * simplified.vertices[t[1]] +
               double(4 - i - j) * simplified.vertices[t[2]]) /
              4.0;
          worst = std::max(worst, std::abs(glm::length(p) - 1.0));
        }
    std::printf(
        "limit %.3f: %zu of %zu triangles, measured %.5f, largest distance to the "
        "sphere %.5f (%.5f before)\n",
        limit, simplified.triangles.size(), before, measured, worst, original);
    EXPECT_LE(worst, limit + original);
  }
  // An open square: its border vertices all stay.
  const test::Converted plane = test::convertAndLoad(test::scanOf("plane", 20000), dir / "p.iso");
  TriangleMesh sheet = extractMesh(plane.surface);
  const auto border = borderVertices(sheet);
  ASSERT_GT(border.size(), 10u);
  MeshAttributes none;
  simplifyMesh(sheet, none, 0.01);
  EXPECT_EQ(borderVertices(sheet), border);
}

}  // namespace
}  // namespace iso

namespace iso {
namespace {

// Every tile of a tileset, depth first, with its parent's index (none for the root).
void collectTiles(const nlohmann::json& tile, int parent,
                  std::vector<std::pair<nlohmann::json, int>>& out) {
  const int self = int(out.size());
  out.push_back({tile, parent});
  if (tile.contains("children"))
    for (const nlohmann::json& child : tile["children"]) collectTiles(child, self, out);
}

// A 40k-point sphere's tileset with small tiles (many levels): cut 2 levels below each cell,
// at most 300 leaves a finest tile, two coarser tiles of the frame.
TilesOptions smallTiles() {
  TilesOptions options;
  options.contentLevels = 2;
  options.finestLeaves = 300;
  options.coarserTiles = 2;
  return options;
}

// A tile's content as written (16-bit positions back in world units, z up), surface only.
TriangleMesh contentOf(const std::filesystem::path& directory, const nlohmann::json& tile,
                       const glm::dvec3& offset, bool skirts) {
  const std::filesystem::path path = directory / tile["content"]["uri"].get<std::string>();
  const std::vector<std::byte> raw = test::readFile(path);
  const TriangleMesh mesh =
      decodeGlb(std::vector<uint8_t>(reinterpret_cast<const uint8_t*>(raw.data()),
                                     reinterpret_cast<const uint8_t*>(raw.data()) + raw.size()),
                path.string(), !skirts);
  TriangleMesh out{{}, mesh.triangles};
  for (const glm::dvec3& g : mesh.vertices)
    out.vertices.push_back(glm::dvec3(g.x, -g.z, g.y) + offset);
  return out;
}

// The largest distance from points of `from` (a grid of `grid` steps an edge on each triangle) to
// `onto`, by its closest points: an independent, denser sampling than the exporter's.
double denseDistance(const TriangleMesh& from, const Shape& onto, int grid) {
  double worst = 0.0;
  for (const auto& t : from.triangles)
    for (int i = 0; i <= grid; ++i)
      for (int j = 0; i + j <= grid; ++j) {
        const glm::dvec3 q = (double(i) * from.vertices[t[0]] + double(j) * from.vertices[t[1]] +
                              double(grid - i - j) * from.vertices[t[2]]) /
                             double(grid);
        worst = std::max(worst, onto.closest(q).distance);
      }
  return worst;
}

TEST(Tiles, followTheOctreeWithErrorsMeasuredAgainstTheFinestThatHalveLevelByLevel) {
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(test::scanOf("sphere", 40000), dir / "s.iso");
  const Reader reader = Reader::open(dir / "s.iso");
  std::filesystem::create_directories(dir / "tiles");
  size_t calls = 0;
  const TilesStats stats =
      writeTiles(reader, dir / "tiles", smallTiles(), [&](size_t done, size_t total) {
        ++calls;
        EXPECT_LE(done, total);
      });
  EXPECT_GE(calls, stats.tiles);
  ASSERT_GE(stats.levels.size(), 5u);
  EXPECT_LE(stats.largestChildRatio, 0.5 + 1e-12);

  const nlohmann::json tileset =
      nlohmann::json::parse(std::ifstream(dir / "tiles" / "tileset.json"));
  EXPECT_EQ(tileset["asset"]["version"], "1.1");
  const Frame& frame = reader.header().frame;
  const nlohmann::json& transform = tileset["root"]["transform"];
  const glm::dvec3 offset(frame.origin[0], frame.origin[1], frame.origin[2]);
  for (int a = 0; a < 3; ++a)
    EXPECT_DOUBLE_EQ(transform[12 + a].get<double>(), frame.origin[size_t(a)]);
  EXPECT_GE(tileset["geometricError"].get<double>(),
            tileset["root"]["geometricError"].get<double>());
  std::vector<std::pair<nlohmann::json, int>> tiles;
  collectTiles(tileset["root"], -1, tiles);
  EXPECT_EQ(tiles.size(), stats.tiles);
  const double spacing = c.report["spacing"].get<double>();
  size_t finestTriangles = 0;
  std::vector<std::pair<glm::dvec3, size_t>> onFaces;  // (position, tile)
  double largestStep = 0.0;
  for (size_t k = 0; k < tiles.size(); ++k) {
    const auto& [tile, parent] = tiles[k];
    const nlohmann::json& box = tile["boundingVolume"]["box"];
    ASSERT_EQ(box.size(), 12u);
    const glm::dvec3 centre(box[0], box[1], box[2]);
    const double half = box[3].get<double>();
    EXPECT_EQ(tile["refine"], "REPLACE");
    const double error = tile["geometricError"].get<double>();
    if (parent >= 0) {  // the parent's cell or an octant of it; at most half its error
      const nlohmann::json& outer = tiles[size_t(parent)].first;
      const nlohmann::json& pbox = outer["boundingVolume"]["box"];
      const double phalf = pbox[3].get<double>();
      EXPECT_TRUE(std::abs(half - phalf) < 1e-12 * phalf ||
                  std::abs(2 * half - phalf) < 1e-12 * phalf);
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(centre[a] - half, pbox[a].get<double>() - phalf - 1e-12);
        EXPECT_LE(centre[a] + half, pbox[a].get<double>() + phalf + 1e-12);
      }
      EXPECT_LE(error, 0.5 * outer["geometricError"].get<double>() * (1 + 1e-12));
    }
    const bool finest = !tile.contains("children");
    if (finest) {
      EXPECT_EQ(error, 0.0);
    } else {
      EXPECT_GT(error, 0.0);
    }
    if (!tile.contains("content")) continue;
    const TriangleMesh content = contentOf(dir / "tiles", tile, offset, true);
    const double step = 2.0 * half / 65532.0 + 1e-12;  // at most
    for (const auto& t : content.triangles)
      for (uint32_t v : t) {
        const glm::dvec3 local = content.vertices[v] - offset;
        for (int a = 0; a < 3; ++a) {  // inside the box (skirts too)
          ASSERT_GE(local[a], centre[a] - half - step);
          ASSERT_LE(local[a], centre[a] + half + step);
        }
      }
    if (!finest) continue;
    const TriangleMesh surface = contentOf(dir / "tiles", tile, offset, false);
    finestTriangles += surface.triangles.size();
    for (const auto& t : surface.triangles)
      for (uint32_t v : t) {
        const glm::dvec3& world = surface.vertices[v];
        ASSERT_LT(std::abs(glm::length(world) - 1.0), 0.5 * spacing);
        const glm::dvec3 local = world - offset;
        for (int a = 0; a < 3; ++a)  // on a face of the tile's box: shared with a neighbour
          if (std::abs(std::abs(local[a] - centre[a]) - half) <= 1e-9 * half) {
            onFaces.push_back({local, k});
            break;
          }
      }
    largestStep = std::max(largestStep, step);
  }
  // The finest tiles together are the whole surface's mesh, cut by cell and collapsed.
  const size_t whole = extractMesh(c.surface).triangles.size();
  EXPECT_LT(finestTriangles, whole * 3 / 4);
  EXPECT_GT(finestTriangles, whole / 20);
  std::printf("%llu tiles over %zu levels; finest tiles: %zu triangles (%zu unsimplified)\n",
              static_cast<unsigned long long>(stats.tiles), stats.levels.size(), finestTriangles,
              whole);
  const TilesetCut finestCut = readTilesetCut(dir / "tiles");
  EXPECT_EQ(finestCut.mesh.triangles.size(), finestTriangles);
  EXPECT_EQ(finestCut.geometricError, 0.0);
  // Every depth: each tile within its stated error of the finest tiles below it, as the tileset
  // checks it and sampled three times as densely both ways here.
  const std::unique_ptr<Shape> finestShape = makeMeshShape(finestCut.mesh);
  for (int depth = 0; depth < int(stats.levels.size()); ++depth) {
    const TilesetCheck check = checkTilesetCut(dir / "tiles", depth);
    EXPECT_EQ(check.beyond, 0u) << "depth " << depth;
    EXPECT_LE(check.worstRatio, 1.0) << "depth " << depth;
    const TilesetCut cut = readTilesetCut(dir / "tiles", depth);
    std::printf("depth %d: %llu tiles, %zu triangles, stated %.5f, measured %.5f\n", depth,
                static_cast<unsigned long long>(cut.tiles), cut.mesh.triangles.size(),
                cut.geometricError, check.largest);
    if (depth > 0) continue;
    // The root: dense samples of it to the finest, of the finest to it, and both to the sphere.
    const std::unique_ptr<Shape> rootShape = makeMeshShape(cut.mesh);
    const double dense = std::max(denseDistance(cut.mesh, *finestShape, 12),
                                  denseDistance(finestCut.mesh, *rootShape, 3));
    std::printf("the root: %.5f from the finest (dense samples), stated %.5f\n", dense,
                cut.geometricError);
    EXPECT_LE(dense, cut.geometricError);
    double worst = 0.0;
    for (const glm::dvec3& v : cut.mesh.vertices)
      worst = std::max(worst, std::abs(glm::length(v) - 1.0));
    EXPECT_LE(worst, cut.geometricError + 0.5 * spacing);
  }
  // Where two finest tiles meet, every vertex on one's face is a vertex of another (within the
  // two tiles' 16-bit steps): no cracks between them.
  std::sort(onFaces.begin(), onFaces.end(),
            [](const auto& a, const auto& b) { return a.first.x < b.first.x; });
  size_t matched = 0;
  for (size_t i = 0; i < onFaces.size(); ++i) {
    bool found = false;
    for (size_t j = i; j-- > 0 && onFaces[i].first.x - onFaces[j].first.x <= largestStep && !found;)
      found = onFaces[j].second != onFaces[i].second &&
              glm::length(onFaces[j].first - onFaces[i].first) <= 2.0 * largestStep;
    for (size_t j = i + 1;
         j < onFaces.size() && onFaces[j].first.x - onFaces[i].first.x <= largestStep && !found;
         ++j)
      found = onFaces[j].second != onFaces[i].second &&
              glm::length(onFaces[j].first - onFaces[i].first) <= 2.0 * largestStep;
    matched += found;
  }
  std::printf("%zu of %zu vertices on the finest tiles' faces have a partner in another tile\n",
              matched, onFaces.size());
  ASSERT_GT(onFaces.size(), 100u);
  EXPECT_EQ(matched, onFaces.size());
}

// What a client draws from `eye`: a tile is refined (replaced by its children) where its
// screen-space error, its geometric error over the distance to its box in pixels of a 40°
// 768-pixel-high view, exceeds `target` pixels (3d-tiles-renderer's rule); the tiles drawn, in
// world units, with their skirts when asked, and the depths they are at.
void screenCut(const std::filesystem::path& directory, const nlohmann::json& tile,
               const glm::dvec3& offset, const glm::dvec3& eye, double target, bool skirts,
               int depth, TriangleMesh& out, std::set<int>& depths) {
  const nlohmann::json& box = tile["boundingVolume"]["box"];
  const glm::dvec3 centre = glm::dvec3(box[0], box[1], box[2]) + offset;
  const double half = box[3].get<double>();
  const glm::dvec3 outside = glm::max(glm::abs(eye - centre) - glm::dvec3(half), glm::dvec3(0.0));
  const double distance = std::max(glm::length(outside), 1e-9);
  const double pixels = tile["geometricError"].get<double>() /
                        (distance * 2.0 * std::tan(20.0 * M_PI / 180.0) / 768.0);
  if (tile.contains("children") && pixels > target) {
    for (const nlohmann::json& child : tile["children"])
      screenCut(directory, child, offset, eye, target, skirts, depth + 1, out, depths);
    return;
  }
  depths.insert(depth);
  if (tile.contains("content")) appendMesh(out, contentOf(directory, tile, offset, skirts));
}

TEST(Tiles, skirtsCloseTheCracksWhereAClientDrawsTilesOfDifferentLevelsSideBySide) {
  // What a client draws from six cameras close to the sphere, at three screen-space errors (cuts
  // that mix levels), against the finest tiles: a ray from the camera that meets the finest
  // surface inside its silhouette but none of the tiles drawn near there goes through a crack
  // between tiles of different levels of detail.
  test::TempDir dir;
  const test::Converted c = test::convertAndLoad(test::scanOf("sphere", 40000), dir / "s.iso");
  const Reader reader = Reader::open(dir / "s.iso");
  const Frame& frame = reader.header().frame;
  const glm::dvec3 offset(frame.origin[0], frame.origin[1], frame.origin[2]);
  constexpr int kRays = 50000;
  const auto raysThrough = [&](const TriangleMesh& drawn, const Shape& finest,
                               const glm::dvec3& eye) {
    const std::unique_ptr<Shape> shape = makeMeshShape(drawn);
    std::mt19937_64 rng(7);
    std::normal_distribution<double> normal;
    size_t through = 0;
    for (int r = 0; r < kRays; ++r) {  // towards points of the unit sphere's ball
      const glm::dvec3 aim = 1.05 *
                             glm::normalize(glm::dvec3(normal(rng), normal(rng), normal(rng))) *
                             std::cbrt(std::uniform_real_distribution<double>(0.0, 1.0)(rng));
      const glm::dvec3 d = glm::normalize(aim - eye);
      // Meeting the finest surface (about the unit sphere) well inside its silhouette, the
      // drawn tiles must be met within 0.2 of it (their errors are smaller); through a crack the
      // ray goes on to the far side.
      const std::optional<double> t = finest.intersect(eye, d, 0.0, 10.0);
      if (!t || std::abs(glm::dot(d, glm::normalize(eye + *t * d))) < 0.5) continue;
      through += !shape->intersect(eye, d, 0.0, *t + 0.2).has_value();
    }
    return through;
  };
  const std::vector<glm::dvec3> eyes = {{1.6, 0, 0},      {-1.2, 0.9, 0.3},   {0, 0, 1.7},
                                        {0.3, -1.5, 0.4}, {-0.8, -0.8, -1.0}, {0.9, 0.9, -0.9}};
  std::map<bool, size_t> misses;
  for (const bool skirts : {false, true}) {
    const std::filesystem::path out = dir / (skirts ? "with" : "without");
    std::filesystem::create_directories(out);
    TilesOptions options = smallTiles();
    options.skirts = skirts;
    const TilesStats stats = writeTiles(reader, out, options);
    EXPECT_EQ(stats.skirtEdges > 0, skirts);
    const nlohmann::json tileset = nlohmann::json::parse(std::ifstream(out / "tileset.json"));
    const std::unique_ptr<Shape> finest = makeMeshShape(readTilesetCut(out).mesh);
    size_t mixed = 0;
    for (const double target : {4.0, 32.0, 128.0})
      for (const glm::dvec3& eye : eyes) {
        TriangleMesh drawn;
        std::set<int> depths;
        screenCut(out, tileset["root"], offset, eye, target, true, 0, drawn, depths);
        mixed += depths.size() >= 2;
        const size_t through = raysThrough(drawn, *finest, eye);
        misses[skirts] += through;
        std::printf(
            "%s skirts, %.0f pixels from (%.1f, %.1f, %.1f): depths %d to %d, %zu of %d rays "
            "through\n",
            skirts ? "with" : "without", target, eye.x, eye.y, eye.z, *depths.begin(),
            *depths.rbegin(), through, kRays);
      }
    EXPECT_GE(mixed, 12u);  // of the 18 cuts
  }
  EXPECT_GT(misses[false], 0u);  // there are cracks to close
  EXPECT_EQ(misses[true], 0u);
  // On one thread the same files, byte for byte.
  {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    std::filesystem::create_directories(dir / "one");
    writeTiles(reader, dir / "one", smallTiles());
  }
  size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "with")) {
    ++files;
    ASSERT_TRUE(test::readFile(entry.path()) ==
                test::readFile(dir / "one" / entry.path().filename()))
        << entry.path();
  }
  EXPECT_EQ(files, size_t(std::distance(std::filesystem::directory_iterator(dir / "one"), {})));
}

}  // namespace
}  // namespace iso
