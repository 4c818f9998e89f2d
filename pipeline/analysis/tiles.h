// 3D Tiles 1.1 of an .iso file's surface (specs/pipeline.md §17): one tile a surface chunk,
// following the file's chunk tree (and one beside the children of a chunk with leaves of its own
// outside their cells), each tile's content a glTF binary of the chunk's surface at its own level
// of detail, simplified within the chunk's geometric error, with skirts where tiles of different
// levels may meet.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include "iso/reader.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct TilesOptions {
  // The finest tiles (no children: nothing refines them, and their geometric error is 0) are
  // collapsed within meshoptimizer's estimate of this share of their leaves' edge, unmeasured
  // (iso eval --tiles measures them against the zero set); 0: not at all.
  double finestCollapse = 1.0 / 32;
  // Positions on a grid of this share of the finest leaves' edge, one grid for every tile (16
  // bits over a tile's box where that grid would need more).
  double positionStep = 1.0 / 16;
  // Skirts where a tile's surface meets a face of its box: strips hanging into the surface from
  // its border, twice as deep as the parent's chunk error (specs/pipeline.md §17).
  bool skirts = true;
};

struct TilesLevel {  // the tiles whose chunks start at one octree level
  int level = 0;
  uint64_t tiles = 0, triangles = 0, bytes = 0;
  double geometricError = 0.0;  // the largest of these tiles' (world units)
  double simplified = 0.0;      // the largest measured simplification distance (world units)
};

struct TilesStats {
  uint64_t tiles = 0, triangles = 0, bytes = 0;  // bytes: the .glb files and tileset.json
  uint64_t skirtEdges = 0;                       // border edges given a skirt
  uint64_t restTiles = 0;  // tiles of a chunk's own leaves beside its children's (in `tiles`)
  std::vector<TilesLevel> levels;  // coarsest first
};

// Write tileset.json and one .glb a tile with content into `directory` (which must exist and
// should be empty). Tiles are made in parallel, each from the chunks around its cell only; the
// files do not depend on the number of threads. `progress` (when set) is called with the tiles
// done and the total. Throws iso::FileError for files that cannot be read or written.
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

}  // namespace iso
