// Cutting the octree into the file's surface chunks: quantization, encoding and writing through
// format/ (pipeline/output/chunks.cpp; the layout is specs/iso-format.md, the choices
// specs/pipeline.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "iso/format.h"
#include "iso/surface.h"
#include "pipeline/base/options.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/points/points.h"

namespace iso {

class Reader;
class Writer;

struct ChunkPlan {
  uint8_t cellLevel = 0;
  uint64_t cellKey = 0;
  uint32_t parent = kNoParent;
  SurfaceTopology topology;
  std::vector<uint32_t> nodes;  // octree nodes in topology order
  uint64_t pointCount = 0;      // input points below the roots
};
std::vector<ChunkPlan> planChunks(const Octree& tree, uint32_t nodeBudget);

struct WritePass {
  std::function<FileHeader(FileHeader)> header;
  std::function<void(const Reader& written, Writer& output)> run;
};

struct WriteInput {
  const Octree* tree;
  const PointSet* points;
  const CornerField* corners;
  const HangingCorners* hanging;
  const LodField* lod;
  Frame frame;
  std::string metadata;  // JSON object
  bool colors = false;
  BuildOptions options;
  std::function<void()> release =
      {};  // when set, called once every chunk is written (frees the above)
  // Passes over the finished file (ambient occlusion, light maps need the finished surface): in
  // order, each copies the file written so far into a new writer, whose header is its `header`
  // of the previous one; the last becomes the output.
  std::vector<WritePass> passes = {};
  // When set, called after the surface chunks (and `release`) to add chunks of other kinds.
  std::function<void(Writer& output, const FileHeader& header)> moreChunks = {};
};
struct WriteStats {
  uint64_t chunks = 0, fileBytesWithoutMetadata = 0;
  uint64_t leafCorners = 0, lodCorners = 0;
};
FileHeader surfaceHeader(const Frame& frame, uint8_t maxLevel, bool colors, int normalBits);
// Plan chunks, encode and write the file with input.metadata. Before the file is moved to the
// output path, `finalMetadata` gets the complete file (under its temporary name, readable with
// iso::Reader) and the stats, and returns the metadata that replaces the first.
WriteStats writeSurfaceFile(const std::filesystem::path& output, const WriteInput& input,
                            const std::function<std::string(const std::filesystem::path&,
                                                            const WriteStats&)>& finalMetadata);

}  // namespace iso
