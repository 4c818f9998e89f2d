// Streaming writer of .iso files.
//
// Chunks are compressed and written to disk as they are added, so memory does not grow with the
// file's size (only 80 bytes per chunk for the table). The file is written under a temporary name
// in the output's directory and renamed to the output path by finish(), after everything was
// flushed to disk; an interrupted or failed write never leaves a file at the output path, and a
// file already there stays untouched until the rename replaces it.
//
// Threading: one Writer is used by one thread at a time.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <span>
#include <string>

#include "iso/format.h"

namespace iso {

struct WriterOptions {
  int zstdLevel = 3;
};

// What the caller says about a chunk; the writer fills in offsets, sizes and the checksum.
struct ChunkDesc {
  uint8_t kind = static_cast<uint8_t>(ChunkKind::Blob);
  uint8_t level = 0;
  uint64_t key = 0;
  uint32_t parent = kNoParent;  // may also be set later with Writer::setParent
  uint64_t pointCount = 0;
  uint32_t nodeCount = 0;
  uint32_t leafCount = 0;
  float geometricError = 0.0f;
  Codec codec = Codec::Zstd;  // zstd is stored raw when compression does not make it smaller
};

class Writer {
 public:
  // Create the temporary file and write the header. Throws iso::InternalError for an invalid
  // header and iso::FileError when the file cannot be created.
  Writer(std::filesystem::path output, const FileHeader& header, WriterOptions options = {});
  ~Writer();  // removes the temporary file unless finish() succeeded
  Writer(Writer&&) noexcept;
  Writer& operator=(Writer&&) noexcept;

  // Compress (when asked and worthwhile), checksum and write one chunk; returns its id (the index
  // in the chunk table, in the order of the calls). Throws iso::InternalError, before writing
  // anything, for a description whose entry a reader would refuse: any rule of an entry on its
  // own in specs/iso-format.md, "Chunk table" (level above the header's maxLevel, key out of
  // range, data over kMaxChunkRawSize, the entry rules of its kind...), which the reader checks
  // with the same code; and iso::FileError when writing fails.
  uint32_t addChunk(const ChunkDesc& desc, std::span<const std::byte> data);

  // Write chunk `info` of another file as that file stores it: `stored` (its stored bytes, which
  // the caller checked), codec, raw size and table fields; returns its id here. Throws as
  // addChunk does for a description this file cannot hold.
  uint32_t copyChunk(const ChunkInfo& info, std::span<const std::byte> stored);
  // Set the parent of a chunk added earlier (parents are often written after their children).
  // Throws iso::InternalError for a chunk whose kind has no parent; the link itself is checked
  // when the table is written (close()).
  void setParent(uint32_t chunk, uint32_t parent);

  // The metadata JSON object, written at finish(). Defaults to "{}".
  void setMetadata(std::string json);

  // Write the chunk table, metadata and trailer, flush, and rename to the output path. Throws
  // iso::InternalError when a parent link or the surface chunks' point counts break the rules of
  // the table (specs/iso-format.md, "Chunk table"), before writing it; iso::FileError on I/O
  // failure; either way nothing appears at the output path. Same as close() then commit().
  void finish();

  // Write the chunk table, metadata and trailer: the temporary file is then a complete .iso file
  // that a Reader can open (to measure what was written), still not at the output path.
  void close();
  // After close(): replace the metadata (and trailer) of the temporary file.
  void replaceMetadata(std::string json);
  // After close(): flush and rename the temporary file to the output path.
  void commit();

  // Remove the temporary file now; the writer cannot be used afterwards.
  void abandon() noexcept;

  uint32_t chunkCount() const;
  uint64_t bytesWritten() const;  // file position so far
  const std::filesystem::path& temporaryPath() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace iso
