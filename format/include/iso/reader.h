// Memory-mapped reader of .iso files.
//
// Opening validates the header, trailer, chunk table and metadata (every offset and size) before
// anything is used, and throws iso::FileError naming the file, the byte offset and the reason
// otherwise. It never crashes and never reads outside the file, whatever its bytes (fuzzed).
// Payloads are not touched until asked for: raw payloads are used in place (zero copy), zstd
// payloads decode into caller-provided buffers.
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

#include "iso/format.h"

namespace iso {

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

  // The stored bytes of a chunk: its data itself when the codec is raw (zero copy).
  std::span<const std::byte> storedPayload(uint32_t id) const;

  // Decode a chunk's data into out, which must hold at least rawSize bytes (iso::InternalError
  // otherwise). Throws iso::FileError when a zstd payload is corrupt. Does not check the checksum.
  void decodePayload(uint32_t id, std::span<std::byte> out) const;

  // Check a chunk's stored bytes against its checksum; throws iso::FileError (file, the payload's
  // offset, "chunk N: checksum mismatch") when they differ.
  void checkPayload(uint32_t id) const;

  // The whole file as mapped.
  std::span<const std::byte> bytes() const;

 private:
  struct Impl;
  explicit Reader(std::shared_ptr<const Impl> impl);
  std::shared_ptr<const Impl> impl_;
};

}  // namespace iso
