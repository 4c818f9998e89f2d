// 3D Tiles 1.1 of an .iso file's surface (specs/pipeline.md §17): one tile a surface chunk,
// following the file's chunk tree, each tile's content a glTF binary of the chunk's surface at
// its own level of detail, simplified within the chunk's geometric error.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include "iso/reader.h"

namespace iso {

struct TilesOptions {
  // How far (world units) the finest tiles may be simplified; 0: they are not (at a tenth of the
  // finest leaf's edge the lion's lost 1 % of their triangles, and the tileset took 3 times as
  // long).
  double finestError = 0.0;
};

struct TilesLevel {  // the tiles whose chunks start at one octree level
  int level = 0;
  uint64_t tiles = 0, triangles = 0, bytes = 0;
  double geometricError = 0.0;  // the largest of these tiles' (world units)
  double simplified = 0.0;      // the largest measured simplification distance (world units)
};

struct TilesStats {
  uint64_t tiles = 0, triangles = 0, bytes = 0;  // bytes: the .glb files and tileset.json
  std::vector<TilesLevel> levels;                // coarsest first
};

// Write tileset.json and one .glb a tile with content into `directory` (which must exist and
// should be empty). Tiles are made in parallel, each from the chunks around its cell only; the
// files do not depend on the number of threads. `progress` (when set) is called with the tiles
// done and the total. Throws iso::FileError for files that cannot be read or written.
TilesStats writeTiles(const Reader& reader, const std::filesystem::path& directory,
                      const TilesOptions& options = {},
                      const std::function<void(size_t, size_t)>& progress = {});

}  // namespace iso
