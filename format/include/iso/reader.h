// Memory-mapped reader of .iso files.
//
// Opening validates the header, trailer, chunk table and metadata (every offset and size) before
// anything is used, and throws iso::FileError naming the file, the byte offset and the reason
// otherwise. It never crashes and never reads outside the file, whatever its bytes (fuzzed).
// Payloads are not touched until asked for, and every way to a chunk's data (payload,
// decodePayload, checkPayload) first checks its stored bytes against its checksum, then, for zstd,
// that the frame can hold exactly rawSize bytes, before it allocates or decodes anything: no caller
// can get damaged data. Raw payloads are used in place (zero copy).
//
// Threading: all const member functions may be called from any number of threads at once.
// The file must not be truncated by another process while it is mapped (the mapping would fault).
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "iso/format.h"

namespace iso {

// A chunk's data as Reader::payload gives it: the file's mapped bytes (zero copy, valid while the
// Reader lives) or decoded bytes it owns. Movable, not copyable.
class ChunkData {
 public:
  explicit ChunkData(std::span<const std::byte> mapped) : bytes_(mapped) {}
  explicit ChunkData(std::vector<std::byte> decoded)
      : decoded_(std::move(decoded)), bytes_(decoded_) {}
  // Moving a vector keeps its buffer, so bytes_ stays valid.
  ChunkData(ChunkData&&) noexcept = default;
  ChunkData& operator=(ChunkData&&) noexcept = default;
  ChunkData(const ChunkData&) = delete;
  ChunkData& operator=(const ChunkData&) = delete;

  std::span<const std::byte> bytes() const { return bytes_; }

 private:
  std::vector<std::byte> decoded_;
  std::span<const std::byte> bytes_;
};

class Reader {
 public:
  // Map and validate the file at path.
  static Reader open(const std::filesystem::path& path);
  // Validate bytes that the caller keeps alive for the reader's lifetime; name is used in errors.
  static Reader fromMemory(std::span<const std::byte> bytes, std::string name);

  const std::string& name() const;
  uint64_t fileSize() const;
  const FileHeader& header() const;
  std::span<const ChunkInfo> chunks() const;
  const ChunkInfo& chunk(uint32_t id) const;  // throws std::out_of_range for a bad id
  std::string_view metadata() const;

  // The data of a chunk, checked (see above; specs/iso-format.md, "What readers check"): the
  // mapped bytes themselves when the codec is raw, else decoded into memory the result owns.
  // Checking hashes the stored bytes once a call. Throws iso::FileError (the file, the payload's
  // offset, "chunk N: REASON") when the data is damaged.
  ChunkData payload(uint32_t id) const;

  // The same, decoded into out, which must hold at least rawSize bytes (iso::InternalError
  // otherwise). For callers that reuse a buffer: one that allocates rawSize bytes for the call
  // should call payload(), which allocates only once the checks have passed.
  void decodePayload(uint32_t id, std::span<std::byte> out) const;

  // The same checks without keeping the data: a zstd payload decodes through a small buffer.
  // Throws iso::FileError as payload() does.
  void checkPayload(uint32_t id) const;

  // The whole file as mapped.
  std::span<const std::byte> bytes() const;

 private:
  struct Impl;
  explicit Reader(std::shared_ptr<const Impl> impl);
  std::shared_ptr<const Impl> impl_;
};

}  // namespace iso
