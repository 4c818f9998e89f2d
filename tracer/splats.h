// The GPU form of the kept points (`iso view --points`): each points chunk as a splat blob (its
// disks in Morton order under a tree of boxes), and the splat index, a tree of boxes over the
// points chunks (subsample chunks above those they thin out). Layouts in shaders/shared.h; the
// tracing in shaders/splats.h; specs/viewer.md, "Splats".
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "iso/format.h"
#include "iso/points.h"
#include "iso/reader.h"

namespace iso::viewer {

// Splat radii are the stored k-NN radii times this (a radius that closes the gaps between
// neighbours of a scan, not wider: specs/viewer.md "Splats").
inline constexpr float kSplatRadiusScale = 0.85f;
// Splats blend within this many radii of the nearest disk behind it (P.splat.x).
inline constexpr float kSplatBlendWindow = 3.0f;

struct SplatIndex {
  std::vector<uint32_t> words;  // the index blob
  uint32_t chunk = 0;           // its chunk number: the file's chunk count (a chunk of its own)
  uint32_t nodes = 0;
  float typicalRadius = 0.0f;   // the median radius of the chunks that are not subsamples
};

// The index of a file's points chunks, or nullopt when it keeps none inside its frame.
std::optional<SplatIndex> buildSplatIndex(const Reader& reader);

// The splat blob of a decoded points chunk: the points inside the frame's cube, radius from the
// stored one (or, for files without radii, the chunk's density) times kSplatRadiusScale.
std::vector<uint32_t> buildSplatBlob(const PointsChunk& points, const ChunkInfo& info);

}  // namespace iso::viewer
