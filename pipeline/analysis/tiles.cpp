// 3D Tiles of an .iso file's surface (pipeline/analysis/tiles.h): a tile an octree cell with
// surface, its content the cell's surface at a cut some levels below it, its error measured
// against its children's content and theirs, children first.
#include "pipeline/analysis/tiles.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <span>
#include <string>

#include "iso/error.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/export.h"
#include "pipeline/analysis/gltf.h"
#include "pipeline/base/files.h"
#include "pipeline/geom/shape.h"

namespace iso {
namespace {

// Decoded chunks kept for the tiles around them (a dragon's chunk is about 2 MB decoded; 128
// took the 10M dragon's tileset over 1 GiB).
constexpr size_t kCachedChunks = 64;
// A child's stated error is at most this share of its parent's.
constexpr double kChildShare = 0.5;
constexpr int kMostContentLevels = 10;
// Steps a triangle edge is cut into when sampling a coarser tile against its children; the
// children's finer triangles are sampled at their corners only.
constexpr int kCoarseGrid = 3, kFineGrid = 0;

struct Tile {
  uint8_t depth = 0;  // in the tileset (the root at 0)
  uint8_t level = 0;  // of the cell
  uint64_t key = 0;
  uint8_t deepest = 0;  // the deepest leaf with surface inside the cell
  uint8_t cut = 0;      // the content's cut level (kMaxLevel: the finest)
  std::vector<uint32_t> children;
  uint32_t parent = kNoNode;
  // Made (children first):
  TriangleMesh mesh;  // world units, before skirts
  MeshAttributes attributes;
  uint64_t triangles = 0, bytes = 0, skirtEdges = 0;
  double toChildren = 0.0;      // measured distance to the children's content, world units
  double positionStep = 0.0;    // the content's 16-bit grid (world units)
  double geometricError = 0.0;  // stated: see makeTile
  bool raised = false;          // the error is twice a child's, more than measured
  bool finest() const { return children.empty(); }
};

std::string contentName(const Tile& tile) {
  return "tile-" + std::to_string(tile.depth) + "-" + std::to_string(tile.key) + ".glb";
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

// The filled leaves whose corners change sign (where the surface is), as (key at the file's
// deepest level, level), in key order: each cell's leaves are then one run.
struct SurfaceLeaf {
  uint64_t deepKey = 0;
  uint8_t level = 0;
};

std::vector<SurfaceLeaf> surfaceLeaves(const Reader& reader,
                                       const SurfaceModel::ChunkSource& source) {
  const uint8_t deepest = reader.header().maxLevel;
  std::vector<uint32_t> ids;
  for (const ChunkInfo& info : reader.chunks())
    if (info.kind == uint8_t(ChunkKind::Surface)) ids.push_back(info.id);
  std::vector<std::vector<SurfaceLeaf>> perChunk(ids.size());
  tbb::parallel_for(size_t(0), ids.size(), [&](size_t c) {
    const std::shared_ptr<const SurfaceChunk> chunk = source(ids[c]);
    for (const SurfaceNode& node : chunk->layout.nodes) {
      if (node.childMask != 0) continue;
      bool negative = false, positive = false;
      for (uint32_t corner : node.corners)
        (chunk->leafValues.distance[corner] < 0.0f ? negative : positive) = true;
      if (negative && positive)
        perChunk[c].push_back({node.key << (3 * (deepest - node.level)), node.level});
    }
  });
  std::vector<SurfaceLeaf> leaves;
  for (const auto& some : perChunk) leaves.insert(leaves.end(), some.begin(), some.end());
  std::sort(leaves.begin(), leaves.end(),
            [](const SurfaceLeaf& a, const SurfaceLeaf& b) { return a.deepKey < b.deepKey; });
  return leaves;
}

// How many levels below a cell its content is cut: the most (up to `most`) at which the cells
// with surface in the frame are at most `cells` (each gives a few triangles), so that a tile's
// content is about that size at any depth (a cell at level L holds about 4^-L of the surface).
int contentLevelsFor(std::span<const SurfaceLeaf> leaves, uint8_t deepestLevel, uint64_t cells,
                     int most) {
  int levels = 1;
  for (int k = 1; k <= std::min(most, int(deepestLevel)); ++k) {
    const int shift = 3 * (deepestLevel - k);
    uint64_t count = 0;
    for (size_t i = 0; i < leaves.size(); ++i)
      count += i == 0 || (leaves[i].deepKey >> shift) != (leaves[i - 1].deepKey >> shift);
    if (count > cells) break;
    levels = k;
  }
  return levels;
}

// The tile of the cell at `level` holding `leaves` (at `depth` of the tileset) and, where a leaf
// inside it is deeper than its content's cut, the tiles of its child cells with leaves.
uint32_t addTiles(std::vector<Tile>& tiles, std::span<const SurfaceLeaf> leaves, uint8_t depth,
                  uint8_t level, uint64_t key, uint8_t deepestLevel, int contentLevels,
                  uint64_t finestLeaves, uint32_t parent) {
  const uint32_t self = uint32_t(tiles.size());
  Tile& tile = tiles.emplace_back();
  tile.depth = depth;
  tile.level = level;
  tile.key = key;
  tile.parent = parent;
  for (const SurfaceLeaf& leaf : leaves) tile.deepest = std::max(tile.deepest, leaf.level);
  // The finest where the cut would be, or where the finest surface is no larger than a coarser
  // tile's content (a flat part of finished leaves, a few deeper ones).
  if (int(tile.deepest) <= int(level) + contentLevels || leaves.size() <= finestLeaves) {
    tile.cut = kMaxLevel;
    return self;
  }
  tile.cut = uint8_t(level + contentLevels);
  const int shift = 3 * (deepestLevel - (level + 1));
  std::vector<uint32_t> children;
  for (size_t first = 0; first < leaves.size();) {
    const uint64_t child = leaves[first].deepKey >> shift;
    size_t last = first + 1;
    while (last < leaves.size() && (leaves[last].deepKey >> shift) == child) ++last;
    children.push_back(addTiles(tiles, leaves.subspan(first, last - first), uint8_t(depth + 1),
                                uint8_t(level + 1), child, deepestLevel, contentLevels,
                                finestLeaves, self));
    first = last;
  }
  tiles[self].children = std::move(children);  // (tiles grew: `tile` may have moved)
  return self;
}

// The tileset's tree: above the frame's cell cut `contentLevels` below it, `coarser` tiles of
// that cell cut a level coarser each (each a level of the tileset: the error halves from one to
// the next there too), then the cells.
std::vector<Tile> tileTree(std::span<const SurfaceLeaf> leaves, uint8_t deepestLevel,
                           int contentLevels, uint64_t finestLeaves, int coarser) {
  std::vector<Tile> tiles;
  coarser = std::max(0, std::min(coarser, contentLevels - 1));
  for (int d = 0; d < coarser; ++d) {
    Tile& tile = tiles.emplace_back();
    tile.depth = uint8_t(d);
    tile.cut = uint8_t(contentLevels - coarser + d);
    tile.parent = d > 0 ? uint32_t(d - 1) : kNoNode;
    for (const SurfaceLeaf& leaf : leaves) tile.deepest = std::max(tile.deepest, leaf.level);
    tile.children = {uint32_t(d + 1)};
  }
  addTiles(tiles, leaves, uint8_t(coarser), 0, 0, deepestLevel, contentLevels, finestLeaves,
           coarser > 0 ? uint32_t(coarser - 1) : kNoNode);
  if (coarser > 0 && tiles[size_t(coarser)].finest()) {  // (a shallow file: no coarser tiles)
    tiles.erase(tiles.begin(), tiles.begin() + coarser);
    tiles[0].depth = 0;
    tiles[0].parent = kNoNode;
  }
  return tiles;
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
  std::vector<uint64_t> uses;  // a << 32 | b, sorted
  uses.reserve(3 * mesh.triangles.size());
  for (const auto& t : mesh.triangles)
    for (size_t e = 0; e < 3; ++e) uses.push_back(uint64_t(t[e]) << 32 | t[(e + 1) % 3]);
  std::sort(uses.begin(), uses.end());
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
  for (size_t i = 0; i < uses.size(); ++i) {
    const uint32_t a = uint32_t(uses[i] >> 32), b = uint32_t(uses[i]);
    const bool once =
        (i == 0 || uses[i - 1] != uses[i]) && (i + 1 == uses.size() || uses[i + 1] != uses[i]);
    if (!once || a == b || std::binary_search(uses.begin(), uses.end(), uint64_t(b) << 32 | a))
      continue;
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

// The largest distance from `from` to `onto` (null: no surface), sampled at its triangles'
// vertices and on each triangle at a grid of `grid` steps an edge (1: its centre; 0: none),
// searched within `limit` (beyond: limit).
double largestDistance(const TriangleMesh& from, const Shape* onto, int grid, double limit) {
  if (from.triangles.empty()) return 0.0;
  if (!onto) return limit;
  const auto distance = [&](const glm::dvec3& p) {
    const std::optional<ClosestPoint> c = onto->closestWithin(p, limit);
    return c ? c->distance : limit;
  };
  std::vector<uint8_t> used(from.vertices.size(), 0);  // (a skirt's vertices are not)
  for (const auto& t : from.triangles)
    for (uint32_t v : t) used[v] = 1;
  const double vertices = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, from.vertices.size(), 2048), 0.0,
      [&](const tbb::blocked_range<size_t>& r, double worst) {
        for (size_t v = r.begin(); v < r.end(); ++v)
          if (used[v]) worst = std::max(worst, distance(from.vertices[v]));
        return worst;
      },
      [](double a, double b) { return std::max(a, b); });
  const double inside = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, from.triangles.size(), 512), 0.0,
      [&](const tbb::blocked_range<size_t>& r, double worst) {
        for (size_t t = r.begin(); t < r.end(); ++t) {
          const auto& tri = from.triangles[t];
          const auto& p = from.vertices;
          if (grid <= 1) {
            if (grid == 1)
              worst = std::max(worst, distance((p[tri[0]] + p[tri[1]] + p[tri[2]]) / 3.0));
            continue;
          }
          for (int i = 0; i <= grid; ++i)
            for (int j = 0; i + j <= grid; ++j) {
              if (i == grid || j == grid || i + j == 0) continue;  // corners
              worst = std::max(worst, distance((double(i) * p[tri[0]] + double(j) * p[tri[1]] +
                                                double(grid - i - j) * p[tri[2]]) /
                                               double(grid)));
            }
        }
        return worst;
      },
      [](double a, double b) { return std::max(a, b); });
  return std::max(vertices, inside);
}

std::unique_ptr<Shape> shapeOf(TriangleMesh mesh) {
  if (mesh.triangles.empty()) return nullptr;
  return makeMeshShape(std::move(mesh));
}

// The distance between two meshes both ways: `coarse` sampled on a grid, `fine` at its vertices
// and triangles' centres.
double distanceBothWays(const TriangleMesh& coarse, const TriangleMesh& fine, double limit) {
  const std::unique_ptr<Shape> fineShape = shapeOf(fine), coarseShape = shapeOf(coarse);
  return std::max(largestDistance(coarse, fineShape.get(), kCoarseGrid, limit),
                  largestDistance(fine, coarseShape.get(), kFineGrid, limit));
}

struct Making {
  const Reader& reader;
  const SurfaceModel::ChunkSource& source;
  const TilesOptions& options;
  std::optional<BakedAppearance> baked;
  std::vector<Tile>& tiles;
  const std::function<void()>& step;
};

// A tile's content: its cell's surface at its cut, from the chunks around the cell so that
// neighbours of one cut agree on shared faces; collapsed within a share of the cut's leaf edge
// where it has children, else of its deepest leaves' edge (unmeasured: makeTile measures it).
void makeContent(const Making& m, Tile& tile) {
  const SurfaceModel::Region region = cellRegion(tile.level, tile.key);
  const SurfaceModel model = SurfaceModel::load(m.reader, region, m.source, tile.cut);
  std::vector<uint32_t> vertexLeaves;
  tile.mesh = extractMesh(model, nullptr, &vertexLeaves, &region);
  if (tile.mesh.triangles.empty()) return;
  tile.attributes = meshAttributes(model, tile.mesh, vertexLeaves, m.baked ? &*m.baked : nullptr);
  const Frame& frame = m.reader.header().frame;
  if (tile.finest()) {
    collapseMesh(tile.mesh, tile.attributes,
                 m.options.finestCollapse * std::ldexp(frame.size, -int(tile.deepest)));
  } else {
    collapseMesh(tile.mesh, tile.attributes,
                 m.options.coarseCollapse * std::ldexp(frame.size, -int(tile.cut)));
  }
  optimizeMeshOrder(tile.mesh, tile.attributes);
}

// The tile and those below it, children first (in parallel). A tile's stated error bounds its
// content's distance to the finest tiles in its cell, as a client decodes them: 0 for the
// finest; otherwise its measured distance to its children's content (both ways, on their 16-bit
// grids) and the largest child's error (the triangle inequality), and at least twice any
// child's.
void makeTile(const Making& m, uint32_t i) {
  tbb::parallel_for(size_t(0), m.tiles[i].children.size(),
                    [&](size_t c) { makeTile(m, m.tiles[i].children[c]); });
  Tile& tile = m.tiles[i];
  makeContent(m, tile);
  const Frame& frame = m.reader.header().frame;
  const double cellEdge = std::ldexp(frame.size, -int(tile.level));
  // Positions on the content's 16-bit grid (what a client decodes is what is measured): the
  // finest leaves' share, or 16 bits over the box where that needs more (skirts stay inside it;
  // the grid's first point may lie a step below the box).
  tile.positionStep =
      std::max(m.options.positionStep * std::ldexp(frame.size, -int(m.reader.header().maxLevel)),
               cellEdge / 65532.0);
  const glm::dvec3 origin(frame.origin[0], frame.origin[1], frame.origin[2]);
  for (glm::dvec3& v : tile.mesh.vertices)
    v = origin + glm::round((v - origin) / tile.positionStep) * tile.positionStep;
  if (!tile.finest()) {
    TriangleMesh below;
    double childError = 0.0;
    for (uint32_t c : tile.children) {
      appendMesh(below, m.tiles[c].mesh);
      childError = std::max(childError, m.tiles[c].geometricError);
    }
    tile.toChildren = distanceBothWays(tile.mesh, below, 2.0 * std::sqrt(3.0) * cellEdge);
    // (and a step of its grid for the rounding of a client's float decoding)
    const double measured = tile.toChildren + childError + tile.positionStep;
    tile.geometricError = std::max(measured, childError / kChildShare);
    tile.raised = childError / kChildShare > measured;
  }
  m.step();
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
      if (tiles[child].bytes > 0 || !tiles[child].children.empty())
        out["children"].push_back(tileJson(tiles, child, frame));
  }
  return out;
}

}  // namespace

TilesStats writeTiles(const Reader& reader, const std::filesystem::path& directory,
                      const TilesOptions& options,
                      const std::function<void(size_t, size_t)>& progress) {
  if (options.finestLeaves < 1) throw UsageError("a finest tile holds at least one leaf");
  if (options.contentLevels < 0 || options.contentLevels > kMostContentLevels)
    throw UsageError("the tiles' content levels must be 0 (chosen) to " +
                     std::to_string(kMostContentLevels));
  const Frame& frame = reader.header().frame;

  // Decoded chunks, shared by the tiles around them (each loads the chunks around its cell): the
  // last kCachedChunks used (tiles are made depth first, which is spatial).
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

  const std::vector<SurfaceLeaf> leaves = surfaceLeaves(reader, source);
  if (leaves.empty()) throw FileError(reader.name(), std::nullopt, "has no surface");
  const int contentLevels = options.contentLevels > 0
                                ? options.contentLevels
                                : contentLevelsFor(leaves, reader.header().maxLevel,
                                                   4 * options.finestLeaves, kMostContentLevels);
  std::vector<Tile> tiles = tileTree(leaves, reader.header().maxLevel, contentLevels,
                                     options.finestLeaves, options.coarserTiles);

  std::mutex reporting;
  size_t done = 0;
  const size_t steps = 2 * tiles.size();
  const std::function<void()> step = [&] {
    const std::lock_guard lock(reporting);
    ++done;
    if (progress) progress(done, steps);
  };
  const Making making{reader, source, options, bakedAppearance(reader), tiles, step};
  makeTile(making, 0);

  // The contents, with skirts as deep as the tile's own error and twice its parent's (a
  // neighbour drawn unrefined beside it: up to two levels coarser), into their files.
  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t i) {
    Tile& tile = tiles[i];
    if (!tile.mesh.triangles.empty()) {
      TriangleMesh mesh = std::move(tile.mesh);
      MeshAttributes attributes = std::move(tile.attributes);
      const size_t surface = mesh.triangles.size();
      if (options.skirts && tile.parent != kNoNode) {
        const SurfaceModel::Region region = cellRegion(tile.level, tile.key);
        glm::dvec3 lo, hi;
        std::array<std::array<bool, 2>, 3> inside{};
        for (int a = 0; a < 3; ++a) {
          lo[a] = frame.origin[size_t(a)] + region.lo[size_t(a)] * frame.size;
          hi[a] = frame.origin[size_t(a)] + region.hi[size_t(a)] * frame.size;
          inside[size_t(a)] = {region.lo[size_t(a)] > 0.0, region.hi[size_t(a)] < 1.0};
        }
        const double height = tile.geometricError + tiles[tile.parent].geometricError;
        tile.skirtEdges = addSkirts(mesh, attributes, lo, hi, inside, height);
      }
      tile.triangles = surface;
      GlbOptions glb;
      glb.origin = glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]);
      glb.yUp = true;
      glb.unlit = making.baked.has_value();
      // One grid for the tiles of a level, and for all where the finest leaves' share reaches
      // over the box: a vertex tiles share lands on one point in each, whatever their cuts.
      glb.positionStep = tile.positionStep;
      glb.skirtsFrom = surface;
      const std::vector<uint8_t> bytes = encodeGlb(mesh, attributes, glb);
      writeFileBytes(directory / contentName(tile), bytes);
      tile.bytes = bytes.size();
    }
    step();
  });

  // The root's transform puts the frame's origin back: UTM or ECEF coordinates land where they
  // are, and the tiles' own numbers stay small.
  nlohmann::json rootJson = tileJson(tiles, 0, frame);
  rootJson["transform"] = {
      1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, frame.origin[0], frame.origin[1], frame.origin[2], 1};
  const double rootError = tiles[0].geometricError;
  const nlohmann::json tileset = {
      {"asset", {{"version", "1.1"}, {"generator", "iso export"}}},
      // Nothing drawn: off by the frame's diagonal at most (and never below the root's).
      {"geometricError", std::max(std::sqrt(3.0) * frame.size, rootError / kChildShare)},
      {"root", rootJson}};
  const std::string text = tileset.dump(1);
  writeFileBytes(directory / "tileset.json", std::vector<uint8_t>(text.begin(), text.end()));

  TilesStats stats;
  std::map<int, TilesLevel> levels;
  std::map<int, std::vector<double>> errors;
  for (const Tile& tile : tiles) {
    if (tile.bytes == 0 && tile.children.empty()) continue;  // (not in the tileset)
    TilesLevel& l = levels[tile.depth];
    l.level = tile.depth;
    ++l.tiles;
    l.finest += tile.finest();
    l.triangles += tile.triangles;
    l.bytes += tile.bytes;
    if (tile.finest()) l.finestBytes += tile.bytes;
    l.largestTriangles = std::max(l.largestTriangles, tile.triangles);
    l.largestBytes = std::max(l.largestBytes, tile.bytes);
    l.geometricError = std::max(l.geometricError, tile.geometricError);
    l.toChildren = std::max(l.toChildren, tile.toChildren);
    errors[tile.depth].push_back(tile.geometricError);
    stats.tiles += 1;
    stats.raised += tile.raised;
    stats.skirtEdges += tile.skirtEdges;
    stats.triangles += tile.triangles;
    stats.bytes += tile.bytes;
    if (tile.parent != kNoNode && tiles[tile.parent].geometricError > 0.0)
      stats.largestChildRatio = std::max(stats.largestChildRatio,
                                         tile.geometricError / tiles[tile.parent].geometricError);
  }
  stats.bytes += text.size();
  for (auto& [level, l] : levels) {
    std::vector<double>& e = errors[level];
    std::nth_element(e.begin(), e.begin() + ptrdiff_t(e.size() / 2), e.end());
    l.medianError = e[e.size() / 2];
    stats.levels.push_back(l);
  }
  return stats;
}

namespace {

struct TilesetFile {
  std::filesystem::path directory;
  nlohmann::json root;
  glm::dvec3 offset{0.0};
};

TilesetFile readTileset(const std::filesystem::path& directory) {
  const std::filesystem::path path = directory / "tileset.json";
  const std::vector<uint8_t> text = readFileBytes(path);
  TilesetFile file{directory, {}, glm::dvec3(0.0)};
  try {
    const nlohmann::json tileset = nlohmann::json::parse(text.begin(), text.end());
    file.root = tileset.at("root");
    if (file.root.contains("transform"))
      for (int a = 0; a < 3; ++a)
        file.offset[a] = file.root["transform"].at(size_t(12 + a)).get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw FileError(path.string(), std::nullopt, std::string("is not a tileset: ") + e.what());
  }
  return file;
}

bool hasChildren(const nlohmann::json& tile) {
  return tile.contains("children") && !tile["children"].empty();
}

// A tile's content in world units (z up), with its skirts when asked; none without content.
TriangleMesh tileMesh(const TilesetFile& file, const nlohmann::json& tile, bool skirts) {
  TriangleMesh out;
  if (!tile.contains("content")) return out;
  const std::filesystem::path path = file.directory / tile["content"].at("uri").get<std::string>();
  const TriangleMesh mesh = decodeGlb(readFileBytes(path), path.string(), !skirts);
  // (without the skirts' vertices when they are left out)
  std::vector<uint32_t> index(mesh.vertices.size(), kNoNode);
  out.triangles.reserve(mesh.triangles.size());
  for (auto t : mesh.triangles) {
    for (uint32_t& v : t) {
      if (index[v] == kNoNode) {
        index[v] = uint32_t(out.vertices.size());
        const glm::dvec3& g = mesh.vertices[v];  // glTF's y up back to z up
        out.vertices.push_back(glm::dvec3(g.x, -g.z, g.y) + file.offset);
      }
      v = index[v];
    }
    out.triangles.push_back(t);
  }
  return out;
}

void addCut(const TilesetFile& file, const nlohmann::json& tile, int depth, int at, bool skirts,
            TilesetCut& cut) {
  if (!hasChildren(tile) || at == depth) {
    cut.geometricError = std::max(cut.geometricError, tile.at("geometricError").get<double>());
    ++cut.tiles;
    appendMesh(cut.mesh, tileMesh(file, tile, skirts));
    return;
  }
  for (const nlohmann::json& child : tile["children"])
    addCut(file, child, depth, at + 1, skirts, cut);
}

// The finest tiles at or below a tile, as one mesh.
void addFinest(const TilesetFile& file, const nlohmann::json& tile, TriangleMesh& out) {
  if (!hasChildren(tile)) {
    appendMesh(out, tileMesh(file, tile, false));
    return;
  }
  for (const nlohmann::json& child : tile["children"]) addFinest(file, child, out);
}

void checkCut(const TilesetFile& file, const nlohmann::json& tile, int depth, int at,
              TilesetCheck& check) {
  if (hasChildren(tile) && at < depth) {
    for (const nlohmann::json& child : tile["children"])
      checkCut(file, child, depth, at + 1, check);
    return;
  }
  ++check.tiles;
  if (!hasChildren(tile)) return;  // the finest itself
  const double stated = tile.at("geometricError").get<double>();
  TriangleMesh finest;
  addFinest(file, tile, finest);
  const nlohmann::json& box = tile.at("boundingVolume").at("box");
  const double limit = 4.0 * std::sqrt(3.0) * box.at(3).get<double>();
  const double d = distanceBothWays(tileMesh(file, tile, false), finest, limit);
  check.largest = std::max(check.largest, d);
  check.beyond += d > stated;
  if (stated > 0.0) check.worstRatio = std::max(check.worstRatio, d / stated);
}

}  // namespace

TilesetCut readTilesetCut(const std::filesystem::path& directory, int depth, bool skirts) {
  const TilesetFile file = readTileset(directory);
  TilesetCut cut;
  try {
    addCut(file, file.root, depth, 0, skirts, cut);
  } catch (const nlohmann::json::exception& e) {
    throw FileError((directory / "tileset.json").string(), std::nullopt,
                    std::string("is not a tileset: ") + e.what());
  }
  return cut;
}

TilesetCheck checkTilesetCut(const std::filesystem::path& directory, int depth) {
  const TilesetFile file = readTileset(directory);
  TilesetCheck check;
  try {
    checkCut(file, file.root, depth, 0, check);
  } catch (const nlohmann::json::exception& e) {
    throw FileError((directory / "tileset.json").string(), std::nullopt,
                    std::string("is not a tileset: ") + e.what());
  }
  return check;
}

}  // namespace iso
