// laz_decoder.h in a build without the decoder (CMake found no wasm2c or no npm laz-perf): every
// decoder refuses, saying what to install.
#include "pipeline/io/laz_decoder.h"

namespace iso::io {

struct LazChunkDecoder::Instance {};

bool hasLazDecoder() { return false; }

LazChunkDecoder::LazChunkDecoder() { throw LazDecodeError(kLazDecoderMissing); }
LazChunkDecoder::~LazChunkDecoder() = default;

void LazChunkDecoder::open(int, size_t, std::span<const std::byte>) {
  throw LazDecodeError(kLazDecoderMissing);
}

void LazChunkDecoder::decode(size_t, std::byte*) { throw LazDecodeError(kLazDecoderMissing); }

}  // namespace iso::io
