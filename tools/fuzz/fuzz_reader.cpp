// libFuzzer target for the reader: any bytes must give a FileError or a reader whose every call
// (verify, the checked data of every chunk, surface, points, values and lighting chunks, and the
// surface model with a ray, a projection and its leaves' attributes) works, never a crash or
// undefined behaviour. Each input is also tried with its checksums recomputed, so the fuzzer
// reaches the structural checks behind them.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "iso/error.h"
#include "iso/lighting.h"
#include "iso/points.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "iso/verify.h"
#include "tests/support/support.h"

namespace {

void exercise(const std::vector<std::byte>& bytes) {
  try {
    const iso::Reader reader = iso::Reader::fromMemory(bytes, "fuzz.iso");
    iso::verifyFile(reader);
    std::vector<std::byte> out;
    for (const iso::ChunkInfo& c : reader.chunks()) {
      if (c.rawSize > (1u << 20)) continue;  // verifyFile streamed it; spare the fuzzer's memory
      out.resize(c.rawSize);
      try {
        reader.decodePayload(c.id, out);
      } catch (const iso::FileError&) {
      }
      try {
        (void)reader.payload(c.id);
      } catch (const iso::FileError&) {
      }
    }
    (void)reader.metadata();
    for (const iso::ChunkInfo& c : reader.chunks()) {
      if (c.rawSize > (1u << 20)) continue;
      try {
        if (c.kind == iso::kSurfaceKind) iso::decodeSurfaceChunk(reader, c.id);
        if (c.kind == iso::kPointsKind || c.kind == iso::kVolumePointsKind)
          iso::decodePointsChunk(reader, c.id);
        if (c.kind == iso::kValuesKind) iso::decodeValuesChunk(reader, c.id);
        if (c.kind == iso::kLightingKind) iso::decodeLightingChunk(reader, c.id);
      } catch (const iso::FileError&) {
      }
    }
    const iso::SurfaceModel model = iso::SurfaceModel::load(reader);
    // Queries on whatever was decoded must stay inside the model.
    (void)model.intersect({-0.5, 0.3, 0.4}, {1.0, 0.1, 0.05}, 0.0, 10.0);
    (void)model.project({0.4, 0.5, 0.6});
    for (uint32_t leaf = 0; leaf < model.leaves().size() && leaf < 64; ++leaf)
      (void)model.evaluate(leaf, {0.5, 0.5, 0.5});
  } catch (const iso::FileError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<std::byte> bytes(size);
  if (size > 0) std::memcpy(bytes.data(), data, size);
  exercise(bytes);
  iso::test::resealChecksums(bytes);
  exercise(bytes);
  return 0;
}
