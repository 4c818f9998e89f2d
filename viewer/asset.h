// An .iso file opened for viewing: the memory-mapped reader, its chunk tree, what its corner
// records carry, the bounds of its surface and the scene's up direction.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>

#include "iso/reader.h"
#include "tracer/blob.h"
#include "tracer/splats.h"
#include "base/image.h"
#include "viewer/scene.h"

namespace iso::viewer {

struct Asset {
  Reader reader;
  ChunkTree tree;
  BlobOptions blob;
  Bounds bounds;  // world units: the cells of the coarsest chunk's deepest nodes and leaves
  glm::vec3 contentLo{0.0f}, contentHi{1.0f};  // the same box in frame units (exact)
  std::vector<SurfaceCell> cells;  // the coarsest chunk's deepest nodes and leaves: what the
                                   // default camera frames
  Vec3d up{0, 1, 0};
  std::optional<SplatIndex> splats;  // the kept points' splat index, when the file keeps points

  // Throws iso::FileError for files that are not valid or hold no surface.
  static std::unique_ptr<Asset> open(const std::filesystem::path& path);

  explicit Asset(Reader r);  // the reader and its chunk tree only: use open()
};

// The frame setup of the CPU reference tracer for an asset (everything resident, no requests).
FrameSetup cpuFrameSetup(const Asset& asset, uint32_t width, uint32_t height,
                         const Environment* environment);

}  // namespace iso::viewer
