// The GPU form of a surface chunk ("blob", specs/viewer.md): node records that the tracer walks
// with popcounts, corner records with the file's distance codes, octahedral normals and sRGB
// colors, and for cut nodes the links to the roots of the child chunks. Built on the CPU by the
// loader thread.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "iso/format.h"
#include "iso/surface.h"
#include "shaders/shared.h"

namespace iso::viewer {

// What the blobs of a file need from its chunk table.
class ChunkTree {
 public:
  explicit ChunkTree(std::span<const ChunkInfo> chunks);
  // The child chunk of `parent` whose cell contains the cell (level, key), or kNoParent.
  uint32_t childCovering(uint32_t parent, uint8_t level, uint64_t key) const;
  uint32_t topChunk() const { return top_; }  // the surface chunk holding the root, or kNoParent
  float geometricError(uint32_t chunk) const { return chunks_[chunk].geometricError; }

 private:
  std::span<const ChunkInfo> chunks_;
  std::vector<std::vector<uint32_t>> children_;  // per chunk, its surface child chunks
  uint32_t top_ = kNoParent;
};

struct BlobOptions {
  bool normals = false;    // the records carry normals
  bool colors = false;     // the records carry colors
  bool occlusion = false;  // ... and occlusion (in the color words, white without colors)
  // The file has lighting chunks: the records carry the baked irradiance (RGB9E5), whose chunk
  // for each surface chunk is lightingOf[id] (kNoParent: none, its corners receive nothing).
  bool irradiance = false;
  std::shared_ptr<const std::vector<uint32_t>> lightingOf;
  // Distances as float32 (files whose distances are not snorm8), else as the file's codes.
  bool floatDistances = false;
  float distanceUnit = 0.0f;  // a code's unit at level 0: float(√3 · the distance scale)
};

// What a file's corner records carry, from its attributes and its lighting chunks.
BlobOptions blobOptionsOf(const Reader& reader);

// Surface chunk `id` decoded, with its lighting when the records carry irradiance.
SurfaceChunk decodeBlobChunk(const Reader& reader, uint32_t id, const BlobOptions& options);

// Words per corner record with these options.
uint32_t recordWords(const BlobOptions& options);

// The option bits of FrameParams.options.x that say what records carry (kOptionNormals, ...).
uint32_t recordOptionBits(const BlobOptions& options);

// Fills FrameParams.srgbToLinear, the table that decodes the records' sRGB colors, and
// FrameParams.srgbBounds, where the code of a pixel's linear value rises.
void setColorTable(gpu::FrameParams& params);

// The blob of a decoded chunk: header, node records, cut nodes' links, a corner record per node
// (shaders/shared.h). Contiguous: the pool holds it in consecutive words.
std::vector<uint32_t> buildBlob(const SurfaceChunk& chunk, uint32_t id, const ChunkTree& tree,
                                const BlobOptions& options);

// The geometric error of drawing each node of a chunk in place of what is below it (frame units):
// 0 for leaves; the chunk's error for its cut nodes (their children are other chunks' roots);
// for other nodes, the largest over their children of the child's error plus the distance between
// the node's patch and the child's at the child's corners.
std::vector<float> nodeErrors(const SurfaceChunk& chunk, float chunkError, uint32_t lastLevel);

// A node's error as the 8-bit code of its node record (shared.h, kNodeErrorShift): 0 for none,
// else the error over the node's edge rounded up to an eighth of a power of two, 255 for 2^15.875
// edges or more (never drawn in place of its children).
uint32_t encodeNodeError(double error, uint8_t level);

// Pages a blob of `words` words spans in the pool.
uint32_t blobPages(size_t words);

}  // namespace iso::viewer
