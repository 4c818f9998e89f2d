// LASzip chunks decoded by laz-perf 3 (the LAZ codec PDAL uses): npm's WebAssembly build of it,
// compiled to C at build time by wabt's wasm2c and run in this process, one instance of the
// module per decoder. The module's memory is its own (every access is bounds-checked), so a
// damaged or hostile chunk can make a decoder fail, never corrupt the host. A decoder is used by
// one thread at a time; several decoders run in parallel.
#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <stdexcept>

namespace iso::io {

// Whether this build holds the decoder (CMake found wabt's wasm2c and npm's laz-perf).
bool hasLazDecoder();

// What a build without the decoder says of a LAZ file.
inline constexpr const char* kLazDecoderMissing =
    "this build of iso has no LAZ decoder: install Debian's wabt and npm's laz-perf "
    "(`tools/run setup` does both), then build again (`tools/run build`)";

// The largest compressed chunk a decoder takes.
inline constexpr size_t kMaxLazChunkBytes = size_t{512} << 20;

// The decoder failed on a chunk: its data is damaged (or the decoder is missing).
class LazDecodeError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class LazChunkDecoder {
 public:
  // Throws LazDecodeError when the build has no decoder.
  LazChunkDecoder();
  ~LazChunkDecoder();
  LazChunkDecoder(const LazChunkDecoder&) = delete;
  LazChunkDecoder& operator=(const LazChunkDecoder&) = delete;

  // Begin a chunk of point data format `format` (0–3 or 6–8) whose records are `recordLength`
  // bytes (the format's own and extra bytes); the chunk's bytes are copied into the decoder.
  void open(int format, size_t recordLength, std::span<const std::byte> chunk);
  // Decode the next `count` records of the open chunk into out (count × recordLength bytes).
  // Throws LazDecodeError when the decoder fails; the decoder then needs a new open().
  void decode(size_t count, std::byte* out);
  // The bytes the decoder's module holds now: a chunk may grow them by about twice its own size
  // and 16 MiB, and no further (its declared layer sizes are checked against that, not trusted).
  size_t memoryBytes() const;

 private:
  struct Instance;
  std::unique_ptr<Instance> instance_;
  int format_ = 0;
  size_t recordLength_ = 0;
};

}  // namespace iso::io
