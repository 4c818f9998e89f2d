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

TEST(Tiles, followTheChunkTreeWithContentInsideEachTilesBoxAndTheFinestOnTheSurface) {
  test::TempDir dir;
  BuildOptions options;
  options.chunkNodes = 2000;  // many chunks, over several levels
  const test::Converted c =
      test::convertAndLoad(test::scanOf("sphere", 40000), dir / "s.iso", options);
  const Reader reader = Reader::open(dir / "s.iso");
  std::filesystem::create_directories(dir / "tiles");
  size_t calls = 0;
  const TilesStats stats = writeTiles(reader, dir / "tiles", {}, [&](size_t done, size_t total) {
    ++calls;
    EXPECT_LE(done, total);
  });
  size_t surfaceChunks = 0;
  for (const ChunkInfo& info : reader.chunks())
    surfaceChunks += info.kind == uint8_t(ChunkKind::Surface);
  ASSERT_GT(surfaceChunks, 8u);
  // A tile a chunk, and one for the rest of each chunk with children that has leaves of its own
  // outside theirs.
  EXPECT_EQ(stats.tiles, surfaceChunks + stats.restTiles);
  EXPECT_GE(calls, stats.tiles);
  EXPECT_GE(stats.levels.size(), 2u);

  const nlohmann::json tileset =
      nlohmann::json::parse(std::ifstream(dir / "tiles" / "tileset.json"));
  EXPECT_EQ(tileset["asset"]["version"], "1.1");
  const Frame& frame = reader.header().frame;
  const nlohmann::json& transform = tileset["root"]["transform"];
  for (int a = 0; a < 3; ++a)
    EXPECT_DOUBLE_EQ(transform[12 + a].get<double>(), frame.origin[size_t(a)]);
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
    if (parent >= 0) {  // inside the parent's box, with no larger an error
      const nlohmann::json& outer = tiles[size_t(parent)].first;
      const nlohmann::json& pbox = outer["boundingVolume"]["box"];
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(centre[a] - half, pbox[a].get<double>() - pbox[3].get<double>() - 1e-12);
        EXPECT_LE(centre[a] + half, pbox[a].get<double>() + pbox[3].get<double>() + 1e-12);
      }
      EXPECT_LE(error, outer["geometricError"].get<double>());
    }
    const bool finest = !tile.contains("children");
    if (finest) {
      EXPECT_EQ(error, 0.0);
    }
    if (!tile.contains("content")) continue;
    // The content: y up in the file (x, z, -y), about the frame's origin; inside the box, and for
    // the finest tiles within half a spacing of the unit sphere.
    const std::filesystem::path path = dir / "tiles" / tile["content"]["uri"].get<std::string>();
    const std::vector<std::byte> raw = test::readFile(path);
    const Glb glb =
        parseGlb(std::vector<uint8_t>(reinterpret_cast<const uint8_t*>(raw.data()),
                                      reinterpret_cast<const uint8_t*>(raw.data()) + raw.size()));
    const nlohmann::json& node = glb.json["nodes"][0];
    const glm::dvec3 t(node["translation"][0], node["translation"][1], node["translation"][2]);
    const double step = node["scale"][0].get<double>();
    const std::vector<uint8_t> positions = viewBytes(glb, 0);
    const size_t count = glb.json["accessors"][0]["count"].get<size_t>();
    for (size_t i = 0; i < count; ++i) {
      uint16_t q[3];
      std::memcpy(q, positions.data() + 8 * i, 6);
      const glm::dvec3 up = t + step * glm::dvec3(q[0], q[1], q[2]);
      const glm::dvec3 local(up.x, -up.z, up.y);  // back to z up
      for (int a = 0; a < 3; ++a) {
        ASSERT_GE(local[a], centre[a] - half - step);
        ASSERT_LE(local[a], centre[a] + half + step);
      }
      if (finest) {
        const glm::dvec3 world =
            local + glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]);
        ASSERT_LT(std::abs(glm::length(world) - 1.0), 0.5 * spacing);
        for (int a = 0; a < 3; ++a)  // on a face of the tile's box: shared with a neighbour
          if (std::abs(std::abs(local[a] - centre[a]) - half) <= step) {
            onFaces.push_back({local, k});
            break;
          }
        largestStep = std::max(largestStep, step);
      }
    }
    if (finest)  // the first primitive's (the second holds skirts)
      finestTriangles +=
          glb.json["accessors"][glb.json["meshes"][0]["primitives"][0]["indices"].get<size_t>()]
                  ["count"]
                      .get<size_t>() /
          3;
  }
  // The finest tiles together are the whole surface's mesh, cut by chunk and collapsed; read back
  // as one mesh (world units), on the sphere. A coarser cut is within its stated error of the
  // finest surface, which is within half a spacing of the sphere.
  const size_t whole = extractMesh(c.surface).triangles.size();
  EXPECT_LT(finestTriangles, whole * 3 / 4);
  EXPECT_GT(finestTriangles, whole / 20);
  std::printf("finest tiles: %zu triangles (%zu unsimplified)\n", finestTriangles, whole);
  const TilesetCut finestCut = readTilesetCut(dir / "tiles");
  EXPECT_EQ(finestCut.mesh.triangles.size(), finestTriangles);
  EXPECT_EQ(finestCut.geometricError, 0.0);
  for (const glm::dvec3& v : finestCut.mesh.vertices)
    ASSERT_LT(std::abs(glm::length(v) - 1.0), 0.5 * spacing);
  const TilesetCut top = readTilesetCut(dir / "tiles", 0);
  EXPECT_EQ(top.tiles, 1u);
  ASSERT_GT(top.geometricError, 0.0);
  double topWorst = 0.0;
  for (const glm::dvec3& v : top.mesh.vertices)
    topWorst = std::max(topWorst, std::abs(glm::length(v) - 1.0));
  std::printf("the root tile: %zu triangles, %.4f from the sphere, stated error %.4f\n",
              top.mesh.triangles.size(), topWorst, top.geometricError);
  EXPECT_LE(topWorst, top.geometricError + 0.5 * spacing);
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

// A cut that mixes levels: depth first, every other tile with children refined, the rest drawn
// as they are; its tiles' triangles in world units (with their skirts when asked).
void addMixedCut(const std::filesystem::path& directory, const nlohmann::json& tile,
                 const glm::dvec3& offset, bool skirts, size_t& turn, TriangleMesh& out) {
  const bool children = tile.contains("children") && !tile["children"].empty();
  if (children && turn++ % 2 == 0) {
    for (const nlohmann::json& child : tile["children"])
      addMixedCut(directory, child, offset, skirts, turn, out);
    return;
  }
  if (!tile.contains("content")) return;
  const std::filesystem::path path = directory / tile["content"]["uri"].get<std::string>();
  const std::vector<std::byte> raw = test::readFile(path);
  const TriangleMesh mesh =
      decodeGlb(std::vector<uint8_t>(reinterpret_cast<const uint8_t*>(raw.data()),
                                     reinterpret_cast<const uint8_t*>(raw.data()) + raw.size()),
                path.string(), !skirts);
  const uint32_t base = uint32_t(out.vertices.size());
  for (const glm::dvec3& g : mesh.vertices)
    out.vertices.push_back(glm::dvec3(g.x, -g.z, g.y) + offset);
  for (const auto& t : mesh.triangles)
    out.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

TEST(Tiles, skirtsCloseTheCracksWhereTilesOfDifferentCutsMeet) {
  // The sphere is closed: a ray from outside aimed at its centre meets any cut of its tiles,
  // unless it goes through a crack between tiles of different levels of detail.
  test::TempDir dir;
  BuildOptions options;
  options.chunkNodes = 100;  // tiles over three levels of the chunk tree
  const test::Converted c =
      test::convertAndLoad(test::scanOf("sphere", 40000), dir / "s.iso", options);
  const Reader reader = Reader::open(dir / "s.iso");
  constexpr int kRays = 100000;
  const auto raysThrough = [&](const TriangleMesh& mesh) {
    const std::unique_ptr<Shape> shape = makeMeshShape(mesh);
    std::mt19937_64 rng(7);
    std::normal_distribution<double> normal;
    size_t through = 0;
    for (int r = 0; r < kRays; ++r) {
      const glm::dvec3 d = glm::normalize(glm::dvec3(normal(rng), normal(rng), normal(rng)));
      through += !shape->intersect(3.0 * d, -d, 0.0, 3.0).has_value();
    }
    return through;
  };
  std::map<bool, size_t> misses;
  for (const bool skirts : {false, true}) {
    const std::filesystem::path out = dir / (skirts ? "with" : "without");
    std::filesystem::create_directories(out);
    TilesOptions tiles;
    tiles.skirts = skirts;
    const TilesStats stats = writeTiles(reader, out, tiles);
    EXPECT_EQ(stats.skirtEdges > 0, skirts);
    if (!skirts) {
      ASSERT_GE(stats.levels.size(), 3u);
      size_t grandchildren = 0;
      for (const ChunkInfo& info : reader.chunks())
        grandchildren += info.kind == uint8_t(ChunkKind::Surface) && info.parent != kNoParent &&
                         reader.chunk(info.parent).parent != kNoParent;
      ASSERT_GT(grandchildren, 0u);
    }
    const nlohmann::json tileset = nlohmann::json::parse(std::ifstream(out / "tileset.json"));
    const nlohmann::json& transform = tileset["root"]["transform"];
    const glm::dvec3 offset(transform[12], transform[13], transform[14]);
    TriangleMesh mixed;
    size_t turn = 0;
    addMixedCut(out, tileset["root"], offset, true, turn, mixed);
    misses[skirts] = raysThrough(mixed);
    // The finest tiles (and the rest of a chunk beside its children's) and the cut at depth 1:
    // none through them either with skirts; the finest agree on their faces without any.
    const size_t finest = raysThrough(readTilesetCut(out).mesh);
    const size_t depth1 = raysThrough(readTilesetCut(out, 1, true).mesh);
    std::printf(
        "%s skirts (%llu border edges, %llu rest tiles): of %d rays, %zu through the "
        "mixed cut, %zu through the finest, %zu through the cut at depth 1\n",
        skirts ? "with" : "without", static_cast<unsigned long long>(stats.skirtEdges),
        static_cast<unsigned long long>(stats.restTiles), kRays, misses[skirts], finest, depth1);
    EXPECT_EQ(finest, 0u);
    if (skirts) {
      EXPECT_EQ(depth1, 0u);
    }
  }
  EXPECT_GT(misses[false], 0u);  // there are cracks to close
  EXPECT_EQ(misses[true], 0u);
  // On one thread the same files, byte for byte.
  {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    std::filesystem::create_directories(dir / "one");
    writeTiles(reader, dir / "one", {});
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
