// The GPU form of a surface chunk ("blob", specs/viewer.md): node records that the tracer walks
// with popcounts, corner records with the file's distance codes, octahedral normals and sRGB
// colors, and for cut nodes the links to the roots of the child chunks. Built on the CPU by the
// loader thread.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "iso/format.h"
#include "iso/surface.h"

namespace iso::viewer {

// What the blobs of a file need from its chunk table.
class ChunkTree {
 public:
  explicit ChunkTree(std::span<const ChunkInfo> chunks);
  // The child chunk of `parent` whose cell contains the cell (level, key), or kNoParent.
  uint32_t childCovering(uint32_t parent, uint8_t level, uint64_t key) const;
  uint32_t topChunk() const { return top_; }  // the surface chunk holding the root, or kNoParent

 private:
  std::span<const ChunkInfo> chunks_;
  std::vector<std::vector<uint32_t>> children_;  // per chunk, its surface child chunks
  uint32_t top_ = kNoParent;
};

struct BlobOptions {
  bool normals = false;    // the records carry normals
  bool colors = false;     // the records carry colors
  bool occlusion = false;  // ... and occlusion (in the color words, white without colors)
  // Distances as float32 (files whose distances are not snorm8), else as the file's codes.
  bool floatDistances = false;
  float distanceUnit = 0.0f;  // a code's unit at level 0: float(√3 · the distance scale)
};

// What a file's corner records carry, from its attributes.
BlobOptions blobOptionsOf(const FileHeader& header);

// Words per corner record with these options.
uint32_t recordWords(const BlobOptions& options);

// The option bits of FrameParams.options.x that say what records carry (kOptionNormals, ...).
uint32_t recordOptionBits(const BlobOptions& options);

// The blob of a decoded chunk, without its page list (filled in when its pages are known):
// words [kBlobPageList, kBlobPageList + pageCount) are left zero for it.
std::vector<uint32_t> buildBlob(const SurfaceChunk& chunk, uint32_t id, const ChunkTree& tree,
                                const BlobOptions& options);

// Pages a blob of `words` words spans.
uint32_t blobPages(size_t words);

}  // namespace iso::viewer
