// 3D Tiles 1.1 of an .iso file's surface (specs/pipeline.md §17): a tile an octree cell, from the
// frame's cube down, each tile's content the surface inside its cell cut `contentLevels` levels
// below it (a level-of-detail cut) and simplified; a cell's children are the
// child cells with surface, until the cut reaches the finest leaves inside the cell. Each tile's
// geometric error is measured against the finest tiles, so that it halves level by level as the
// octree's cells do. Skirts hang where tiles of different levels may meet.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include "iso/reader.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct TilesOptions {
  // A tile is one of the finest where its cell holds at most this many leaves with surface (a
  // mesh makes about 4 triangles a leaf), or where none is deeper than its content's cut.
  uint64_t finestLeaves = 8192;
  // A tile's content is its cell's surface cut this many levels (K) below the cell; 0: the most
  // at which the frame holds at most 4 × finestLeaves cells with surface (then every tile's
  // content is about that size, a few triangles a cell after simplification).
  int contentLevels = 0;
  // Tiles of the frame's cell above it, cut a level coarser each (K - 1, K - 2, ...): the
  // coarsest levels of the tileset.
  int coarserTiles = 3;
  // Edge collapses (meshoptimizer) within its own estimate of how far vertices move: for tiles
  // with children this share of their cut's leaf edge (what they are is measured against their
  // children), for the finest this share of their deepest leaves' edge (they are the finest
  // surface the others are measured against; iso eval --tiles measures them against the zero
  // set); 0: none.
  double coarseCollapse = 0.25;
  double finestCollapse = 1.0 / 32;
  // Positions on a grid of this share of the finest leaves' edge, one grid for every tile (16
  // bits over a tile's box where that grid would need more).
  double positionStep = 1.0 / 16;
  // Skirts where a tile's surface meets a face of its box inside the frame: strips hanging into
  // the surface from its border, as deep as its own error and twice its parent's.
  bool skirts = true;
};

struct TilesLevel {  // the tiles at one depth of the tileset
  int level = 0;
  uint64_t tiles = 0, finest = 0, triangles = 0, bytes = 0;
  uint64_t finestBytes = 0;                         // of the finest tiles among them
  uint64_t largestTriangles = 0, largestBytes = 0;  // of one tile
  double geometricError = 0.0;  // the largest of these tiles' stated errors (world units)
  double medianError = 0.0;     // their median
  double toChildren = 0.0;      // the largest measured distance to the children's content (world)
};

struct TilesStats {
  uint64_t tiles = 0, triangles = 0, bytes = 0;  // bytes: the .glb files and tileset.json
  uint64_t skirtEdges = 0;                       // border edges given a skirt
  // Tiles whose stated error was raised to twice a child's (measured, it was less).
  uint64_t raised = 0;
  // The largest ratio of a child's stated error to its parent's.
  double largestChildRatio = 0.0;
  std::vector<TilesLevel> levels;  // coarsest first
};

// Write tileset.json and one .glb a tile with content into `directory` (which must exist and
// should be empty). Tiles are made in parallel, children before parents, each from the chunks
// around its cell; the files do not depend on the number of threads. `progress` (when set) is
// called with the steps done and the total. Throws iso::FileError for files that cannot be read
// or written, iso::UsageError for options out of range.
TilesStats writeTiles(const Reader& reader, const std::filesystem::path& directory,
                      const TilesOptions& options = {},
                      const std::function<void(size_t, size_t)>& progress = {});

// What a viewer draws of a tileset that writeTiles wrote when it refines down to `depth` of the
// tileset's tree (the root at 0): the tiles there and those above it without children; -1: every
// tile without children (the finest); their skirts too when asked. For measuring it against the
// file's surface.
struct TilesetCut {
  TriangleMesh mesh;  // world coordinates (z up, the root's transform applied)
  uint64_t tiles = 0;
  double geometricError = 0.0;  // the largest of those tiles' (world units)
};
TilesetCut readTilesetCut(const std::filesystem::path& directory, int depth = -1,
                          bool skirts = false);

// Each tile of the cut at `depth` against the finest tiles below it, both ways (sampled: every
// vertex, and a grid on each triangle), beside the error it states.
struct TilesetCheck {
  uint64_t tiles = 0;       // in the cut
  uint64_t beyond = 0;      // tiles farther from the finest below them than they state
  double largest = 0.0;     // the largest distance of a tile (world units)
  double worstRatio = 0.0;  // the largest distance / stated error of a tile with an error
};
TilesetCheck checkTilesetCut(const std::filesystem::path& directory, int depth);

}  // namespace iso
