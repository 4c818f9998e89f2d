// 3D Tiles of an .iso file's surface (pipeline/analysis/tiles.h): a tile a surface chunk (and a
// rest tile beside a chunk's children), its content the chunk's surface at its own cut, extracted
// from the chunks around its cell.
#include "pipeline/analysis/tiles.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <list>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>

#include "iso/error.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/export.h"
#include "pipeline/analysis/gltf.h"
#include "pipeline/base/files.h"

namespace iso {
namespace {

// Decoded chunks kept for the tiles around them (a dragon's chunk is about 2 MB decoded).
constexpr size_t kCachedChunks = 128;

struct Tile {
  uint32_t chunk = 0;
  uint8_t level = 0;
  uint64_t key = 0;
  double chunkError = 0.0;  // the chunk's geometric error, world units
  std::vector<uint32_t> children;
  uint32_t parent = kNoNode;
  // The rest of a chunk with children: its own leaves outside its children's cells, at full
  // detail, a child tile beside theirs (refinement replaces the chunk's tile by its children's).
  bool rest = false;
  // Made:
  uint64_t triangles = 0, bytes = 0;
  double simplified = 0.0;    // measured distance of the simplified content, world units
  double quantization = 0.0;  // how far the content's 16-bit positions may be from it
  uint64_t skirtEdges = 0;
  double geometricError = 0.0;  // what the tileset says: see finishErrors
};

std::string contentName(const Tile& tile) {
  return "tile-" + std::to_string(tile.chunk) + (tile.rest ? "-rest" : "") + ".glb";
}

SurfaceModel::Region cellRegion(uint8_t level, uint64_t key) {
  const double size = std::ldexp(1.0, -int(level));
  const auto cell = mortonDecode(key);
  SurfaceModel::Region region;
  for (size_t a = 0; a < 3; ++a) {
    region.lo[a] = double(cell[a]) * size;
    region.hi[a] = region.lo[a] + size;
  }
  return region;
}

// Skirts: where the mesh's open border runs along one of `faces` of the tile's box (low and high
// on each axis: those inside the frame, where a neighbour tile lies), a strip in that face hanging
// from each border edge `height` into the surface (against the vertices' normals, along the face).
// A neighbour drawn at another level of detail ends on the same face within the two tiles'
// errors, so the outer of the two strips covers the gap between their borders. Returns the
// border edges given one.
size_t addSkirts(TriangleMesh& mesh, MeshAttributes& attributes, const glm::dvec3& lo,
                 const glm::dvec3& hi, const std::array<std::array<bool, 2>, 3>& faces,
                 double height) {
  // The open edges, in their triangle's direction.
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  for (const auto& t : mesh.triangles)
    for (size_t e = 0; e < 3; ++e) ++uses[{t[e], t[(e + 1) % 3]}];
  const double tolerance = 1e-9 * std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  // The face (2 axis + side) both ends lie on, or -1.
  const auto faceOf = [&](const glm::dvec3& a, const glm::dvec3& b) {
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        const double plane = side ? hi[axis] : lo[axis];
        if (faces[size_t(axis)][size_t(side)] && std::abs(a[axis] - plane) <= tolerance &&
            std::abs(b[axis] - plane) <= tolerance)
          return 2 * axis + side;
      }
    return -1;
  };
  // Vertex normals: the file's, else the triangles' by area.
  std::vector<glm::dvec3> normals(mesh.vertices.size(), glm::dvec3(0.0));
  if (!attributes.normals.empty()) {
    for (size_t v = 0; v < normals.size(); ++v) normals[v] = glm::dvec3(attributes.normals[v]);
  } else {
    for (const auto& t : mesh.triangles) {
      const glm::dvec3 n = glm::cross(mesh.vertices[t[1]] - mesh.vertices[t[0]],
                                      mesh.vertices[t[2]] - mesh.vertices[t[0]]);
      for (uint32_t v : t) normals[v] += n;
    }
  }
  std::map<std::pair<uint32_t, int>, uint32_t> hanging;  // (border vertex, face) → its copy
  const auto below = [&](uint32_t v, int face) {
    const auto [it, added] = hanging.insert({{v, face}, uint32_t(mesh.vertices.size())});
    if (added) {
      glm::dvec3 down = -normals[v];
      down[face / 2] = 0.0;  // along the face
      const double length = glm::length(down);
      down = length > 0.0 ? down / length : glm::dvec3(0.0);
      // (kept inside the box, which bounds the tile's content)
      mesh.vertices.push_back(glm::clamp(mesh.vertices[v] + height * down, lo, hi));
      if (!attributes.normals.empty()) attributes.normals.push_back(attributes.normals[v]);
      if (!attributes.colors.empty()) attributes.colors.push_back(attributes.colors[v]);
    }
    return it->second;
  };
  size_t edges = 0;
  for (const auto& [edge, count] : uses) {
    const auto [a, b] = edge;
    if (count != 1 || uses.count({b, a}) || a == b) continue;
    const int face = faceOf(mesh.vertices[a], mesh.vertices[b]);
    if (face < 0) continue;
    // The strip runs b → a, as the triangle across it would.
    const uint32_t a2 = below(a, face), b2 = below(b, face);
    mesh.triangles.push_back({b, a, a2});
    mesh.triangles.push_back({b, a2, b2});
    ++edges;
  }
  return edges;
}

// How deep a tile's skirts hang: three times the largest chunk error (its simplification is within
// one more, and a finer neighbour's fitted corners may move its border by a third) of the tiles
// that may be drawn unrefined beside it, the tile itself when it has children,
// its siblings and its parent's siblings with children; 0 when none has (refinement replaces a
// parent by all its children at once, so tiles of one parent that have none are drawn together).
double skirtHeight(const std::vector<Tile>& tiles, uint32_t i) {
  double error = tiles[i].children.empty() ? 0.0 : tiles[i].chunkError;
  for (uint32_t up = i, generation = 0; generation < 2 && tiles[up].parent != kNoNode;
       ++generation) {
    up = tiles[up].parent;
    for (uint32_t sibling : tiles[up].children)
      if (!tiles[sibling].children.empty()) error = std::max(error, tiles[sibling].chunkError);
  }
  return 3.0 * error;
}

// A tile's content: the chunk's surface at its last level (the cut a viewer draws when it stops
// at this chunk), from the chunks around its cell so that neighbours agree on shared faces;
// simplified within `budget` where it has one (the coarser tiles), else collapsed within the
// options' share of its leaves' edge (the finest); positions on a grid of a share of that edge.
std::vector<uint8_t> makeContent(const Reader& reader, const SurfaceModel::ChunkSource& source,
                                 Tile& tile, double budget, double skirt,
                                 std::span<const SurfaceModel::Region> without,
                                 const TilesOptions& options) {
  const std::shared_ptr<const SurfaceChunk> chunk = source(tile.chunk);
  const uint8_t cut = uint8_t(chunk->topology.startLevel + chunk->topology.depth - 1);
  const SurfaceModel::Region region = cellRegion(tile.level, tile.key);
  // What is loaded: the cell, or for a rest tile the box of the chunk's own leaves outside its
  // children's cells (the leaves of its cut there; none: no content), so that a rest tile near
  // the root does not load the whole file at full detail.
  SurfaceModel::Region load = region;
  if (tile.rest) {
    const SurfaceModel own = SurfaceModel::load(reader, region, source, cut);
    bool any = false;
    for (const SurfaceModel::Leaf& leaf : own.leaves()) {
      if (leaf.level >= kMaxLevel || leaf.level > cut) continue;
      const SurfaceModel::Region cell = cellRegion(leaf.level, leaf.key);
      const auto inside = [&](const SurfaceModel::Region& r) {
        for (size_t a = 0; a < 3; ++a)
          if (cell.lo[a] < r.lo[a] || cell.hi[a] > r.hi[a]) return false;
        return true;
      };
      if (!inside(region) || std::any_of(without.begin(), without.end(), inside)) continue;
      for (size_t a = 0; a < 3; ++a) {
        load.lo[a] = any ? std::min(load.lo[a], cell.lo[a]) : cell.lo[a];
        load.hi[a] = any ? std::max(load.hi[a], cell.hi[a]) : cell.hi[a];
      }
      any = true;
    }
    if (!any) return {};
  }
  // The finest tiles' neighbours at full detail too, whatever their chunks' depths, so that they
  // agree on the faces they share.
  const SurfaceModel model =
      SurfaceModel::load(reader, load, source, tile.children.empty() ? kMaxLevel : cut);
  std::vector<uint32_t> vertexLeaves;
  TriangleMesh mesh = extractMesh(model, nullptr, &vertexLeaves, &region, without);
  if (mesh.triangles.empty()) return {};
  const std::optional<BakedAppearance> baked = bakedAppearance(reader);
  MeshAttributes attributes = meshAttributes(model, mesh, vertexLeaves, baked ? &*baked : nullptr);
  const Frame& frame = reader.header().frame;
  const double leaf = std::ldexp(frame.size, -int(cut));
  if (budget > 0.0)
    tile.simplified = simplifyMesh(mesh, attributes, budget);
  else
    collapseMesh(mesh, attributes, options.finestCollapse * leaf);
  optimizeMeshOrder(mesh, attributes);
  const size_t surface = mesh.triangles.size();
  if (options.skirts && skirt > 0.0) {
    glm::dvec3 lo, hi;
    std::array<std::array<bool, 2>, 3> inside{};
    for (int a = 0; a < 3; ++a) {
      lo[a] = frame.origin[size_t(a)] + region.lo[size_t(a)] * frame.size;
      hi[a] = frame.origin[size_t(a)] + region.hi[size_t(a)] * frame.size;
      inside[size_t(a)] = {region.lo[size_t(a)] > 0.0, region.hi[size_t(a)] < 1.0};
    }
    tile.skirtEdges = addSkirts(mesh, attributes, lo, hi, inside, skirt);
  }
  tile.triangles = surface;
  GlbOptions glb;
  glb.origin = glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]);
  glb.yUp = true;
  glb.unlit = baked.has_value();
  // One grid for every tile (the finest leaves' share): a vertex tiles share lands on one point
  // in each, whatever their cuts (16 bits over a coarse tile's box where it reaches too far).
  glb.positionStep = options.positionStep * std::ldexp(frame.size, -int(reader.header().maxLevel));
  glb.skirtsFrom = surface;
  GlbStats stats;
  std::vector<uint8_t> bytes = encodeGlb(mesh, attributes, glb, &stats);
  tile.quantization = 0.5 * std::sqrt(3.0) * stats.positionStep;
  return bytes;
}

// Geometric errors, children first: a leaf tile's is 0 (nothing refines it); another's is its
// chunk's error plus its simplification, and never below a child's.
double finishErrors(std::vector<Tile>& tiles, uint32_t i) {
  Tile& tile = tiles[i];
  double error =
      tile.children.empty() ? 0.0 : tile.chunkError + tile.simplified + tile.quantization;
  for (uint32_t child : tile.children) error = std::max(error, finishErrors(tiles, child));
  tiles[i].geometricError = error;
  return error;
}

nlohmann::json tileJson(const std::vector<Tile>& tiles, uint32_t i, const Frame& frame) {
  const Tile& tile = tiles[i];
  // The cell as a box in the tileset's frame (world units, about the frame's origin, z up).
  const SurfaceModel::Region cell = cellRegion(tile.level, tile.key);
  const double half = 0.5 * (cell.hi[0] - cell.lo[0]) * frame.size;
  nlohmann::json box = nlohmann::json::array();
  for (size_t a = 0; a < 3; ++a) box.push_back(0.5 * (cell.lo[a] + cell.hi[a]) * frame.size);
  for (size_t a = 0; a < 3; ++a)
    for (size_t b = 0; b < 3; ++b) box.push_back(a == b ? half : 0.0);
  nlohmann::json out = {{"boundingVolume", {{"box", box}}},
                        {"geometricError", tile.geometricError},
                        {"refine", "REPLACE"}};
  if (tile.bytes > 0) out["content"] = {{"uri", contentName(tile)}};
  if (!tile.children.empty()) {
    out["children"] = nlohmann::json::array();
    for (uint32_t child : tile.children)
      if (!(tiles[child].rest && tiles[child].bytes == 0))  // (all in the other children)
        out["children"].push_back(tileJson(tiles, child, frame));
  }
  return out;
}

}  // namespace

TilesStats writeTiles(const Reader& reader, const std::filesystem::path& directory,
                      const TilesOptions& options,
                      const std::function<void(size_t, size_t)>& progress) {
  const Frame& frame = reader.header().frame;
  std::vector<Tile> tiles;
  std::map<uint32_t, uint32_t> tileOf;  // chunk id → tile
  for (const ChunkInfo& info : reader.chunks())
    if (info.kind == uint8_t(ChunkKind::Surface)) {
      tileOf[info.id] = uint32_t(tiles.size());
      Tile& tile = tiles.emplace_back();
      tile.chunk = info.id;
      tile.level = info.level;
      tile.key = info.key;
      tile.chunkError = double(info.geometricError) * frame.size;
    }
  uint32_t root = kNoNode;
  for (uint32_t i = 0; i < tiles.size(); ++i) {
    const uint32_t parent = reader.chunk(tiles[i].chunk).parent;
    if (parent == kNoParent)
      root = i;
    else {
      tiles[tileOf.at(parent)].children.push_back(i);
      tiles[i].parent = tileOf.at(parent);
    }
  }
  if (root == kNoNode) throw FileError(reader.name(), std::nullopt, "has no surface");
  for (uint32_t i = 0, chunks = uint32_t(tiles.size()); i < chunks; ++i) {
    if (tiles[i].children.empty()) continue;
    Tile rest = tiles[i];
    rest.children.clear();
    rest.parent = i;
    rest.rest = true;
    rest.chunkError = 0.0;
    tiles[i].children.push_back(uint32_t(tiles.size()));
    tiles.push_back(std::move(rest));
  }

  // Decoded chunks, shared by the tiles around them (each loads the chunks around its cell): the
  // last kCachedChunks used (tiles go in file order, which is spatial, a subrange a thread).
  std::mutex caching;
  std::list<std::pair<uint32_t, std::shared_ptr<const SurfaceChunk>>> recent;  // newest first
  std::map<uint32_t, decltype(recent)::iterator> cached;
  const SurfaceModel::ChunkSource source = [&](uint32_t id) {
    {
      const std::lock_guard lock(caching);
      const auto found = cached.find(id);
      if (found != cached.end()) {
        recent.splice(recent.begin(), recent, found->second);
        return found->second->second;
      }
    }
    auto chunk = std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader, id));
    const std::lock_guard lock(caching);
    if (!cached.count(id)) {
      recent.emplace_front(id, chunk);
      cached[id] = recent.begin();
      if (recent.size() > kCachedChunks) {
        cached.erase(recent.back().first);
        recent.pop_back();
      }
    }
    return std::shared_ptr<const SurfaceChunk>(std::move(chunk));
  };
  std::mutex reporting;
  size_t done = 0;
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, tiles.size(), 1), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          Tile& tile = tiles[i];
          const double budget = tile.children.empty() ? 0.0 : tile.chunkError;
          const double skirt = skirtHeight(tiles, uint32_t(i));
          // A rest tile leaves out its siblings' cells.
          std::vector<SurfaceModel::Region> without;
          if (tile.rest)
            for (uint32_t sibling : tiles[tile.parent].children)
              if (!tiles[sibling].rest)
                without.push_back(cellRegion(tiles[sibling].level, tiles[sibling].key));
          const std::vector<uint8_t> content =
              makeContent(reader, source, tile, budget, skirt, without, options);
          if (!content.empty()) {
            writeFileBytes(directory / contentName(tile), content);
            tile.bytes = content.size();
          }
          const std::lock_guard lock(reporting);
          ++done;
          if (progress) progress(done, tiles.size());
        }
      });
  finishErrors(tiles, root);

  // The root's transform puts the frame's origin back: UTM or ECEF coordinates land where they
  // are, and the tiles' own numbers stay small.
  nlohmann::json rootJson = tileJson(tiles, root, frame);
  rootJson["transform"] = {
      1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, frame.origin[0], frame.origin[1], frame.origin[2], 1};
  const nlohmann::json tileset = {
      {"asset", {{"version", "1.1"}, {"generator", "iso export"}}},
      {"geometricError", std::sqrt(3.0) * frame.size},  // nothing drawn: off by the frame at most
      {"root", rootJson}};
  const std::string text = tileset.dump(1);
  writeFileBytes(directory / "tileset.json", std::vector<uint8_t>(text.begin(), text.end()));

  TilesStats stats;
  std::map<int, TilesLevel> levels;
  for (const Tile& tile : tiles) {
    if (tile.rest && tile.bytes == 0) continue;  // (not in the tileset)
    stats.restTiles += tile.rest;
    TilesLevel& l = levels[tile.level];
    l.level = tile.level;
    ++l.tiles;
    l.triangles += tile.triangles;
    l.bytes += tile.bytes;
    l.geometricError = std::max(l.geometricError, tile.geometricError);
    l.simplified = std::max(l.simplified, tile.simplified);
    stats.tiles += 1;
    stats.skirtEdges += tile.skirtEdges;
    stats.triangles += tile.triangles;
    stats.bytes += tile.bytes;
  }
  stats.bytes += text.size();
  for (const auto& [level, l] : levels) stats.levels.push_back(l);
  return stats;
}

namespace {

void addCut(const std::filesystem::path& directory, const nlohmann::json& tile, int depth, int at,
            const glm::dvec3& offset, bool skirts, TilesetCut& cut) {
  const bool leaf = !tile.contains("children") || tile["children"].empty();
  if (leaf || at == depth) {
    cut.geometricError = std::max(cut.geometricError, tile.at("geometricError").get<double>());
    ++cut.tiles;
    if (!tile.contains("content")) return;
    const std::filesystem::path path = directory / tile["content"].at("uri").get<std::string>();
    const TriangleMesh mesh = decodeGlb(readFileBytes(path), path.string(), !skirts);
    const uint32_t base = uint32_t(cut.mesh.vertices.size());
    for (const glm::dvec3& g : mesh.vertices)  // glTF's y up back to z up
      cut.mesh.vertices.push_back(glm::dvec3(g.x, -g.z, g.y) + offset);
    for (const auto& t : mesh.triangles)
      cut.mesh.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
    return;
  }
  for (const nlohmann::json& child : tile["children"])
    addCut(directory, child, depth, at + 1, offset, skirts, cut);
}

}  // namespace

TilesetCut readTilesetCut(const std::filesystem::path& directory, int depth, bool skirts) {
  const std::filesystem::path path = directory / "tileset.json";
  const std::vector<uint8_t> text = readFileBytes(path);
  TilesetCut cut;
  try {
    const nlohmann::json tileset = nlohmann::json::parse(text.begin(), text.end());
    const nlohmann::json& root = tileset.at("root");
    glm::dvec3 offset(0.0);
    if (root.contains("transform"))
      for (int a = 0; a < 3; ++a) offset[a] = root["transform"].at(size_t(12 + a)).get<double>();
    addCut(directory, root, depth, 0, offset, skirts, cut);
  } catch (const nlohmann::json::exception& e) {
    throw FileError(path.string(), std::nullopt, std::string("is not a tileset: ") + e.what());
  }
  return cut;
}

}  // namespace iso
