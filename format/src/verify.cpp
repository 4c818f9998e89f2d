// Verification of the bytes Reader::open does not check (specs/iso-format.md, "What readers
// check"): every chunk's data through the Reader's checked accessors, the rules of the chunk kinds
// this version knows, padding, and the metadata's first bytes.
#include "iso/verify.h"

#include <cstdio>
#include <string_view>

#include "bytes.h"
#include "iso/error.h"
#include "iso/lighting.h"
#include "iso/points.h"
#include "iso/surface.h"

namespace iso {
namespace {

// UTF-8's encoding of U+FEFF, which the metadata does not start with (specs/iso-format.md,
// "Metadata").
constexpr std::string_view kByteOrderMark = "\xEF\xBB\xBF";

// The offset of the first non-zero byte in [begin, end), if any.
std::optional<uint64_t> firstNonZero(std::span<const std::byte> bytes, uint64_t begin,
                                     uint64_t end) {
  for (uint64_t i = begin; i < end; ++i)
    if (bytes[i] != std::byte{0}) return i;
  return std::nullopt;
}

// A chunk's problem as a FileError gives it, without the "chunk N: " that describe() replaces.
VerifyProblem chunkProblem(const ChunkInfo& c, const FileError& error) {
  const std::string prefix = "chunk " + std::to_string(c.id) + ": ";
  std::string reason = error.reason();
  if (reason.starts_with(prefix)) reason.erase(0, prefix.size());
  return {c.id, c.offset, reason};
}

// Check a chunk's data (its checksum, its zstd frame) and, for the kinds this version knows, the
// rules of "Surface chunks", "Points chunks", "Values chunks" and "Lighting chunks"; the data of
// other kinds is decoded through a small buffer and dropped.
void checkChunk(const Reader& reader, const ChunkInfo& c, VerifyResult& result) {
  try {
    if (c.kind == kSurfaceKind)
      decodeSurfaceChunk(reader, c.id);
    else if (c.kind == kPointsKind || c.kind == kVolumePointsKind)
      decodePointsChunk(reader, c.id);
    else if (c.kind == kValuesKind)
      decodeValuesChunk(reader, c.id);
    else if (c.kind == kLightingKind) {
      // Its corners are those of its surface chunk (whose own problems are that chunk's).
      const ChunkLighting lighting = decodeLightingChunk(reader, c.id);
      SurfaceChunk surface;
      try {
        surface = decodeSurfaceChunk(reader, lighting.surfaceChunk);
      } catch (const FileError&) {
        return;
      }
      attachLighting(reader, c.id, lighting.surfaceChunk, surface);
    } else
      reader.checkPayload(c.id);
  } catch (const FileError& error) {
    result.problems.push_back(chunkProblem(c, error));
  }
}

}  // namespace

VerifyResult verifyFile(const Reader& reader) {
  VerifyResult result;
  const std::span<const std::byte> bytes = reader.bytes();
  const uint64_t alignment = reader.header().payloadAlignment();
  const auto checkPadding = [&](std::optional<uint32_t> chunk, uint64_t begin) {
    const uint64_t end = detail::alignUp(begin, alignment);
    if (std::optional<uint64_t> at = firstNonZero(bytes, begin, end))
      result.problems.push_back({chunk, *at, "padding byte is not zero"});
  };

  checkPadding(std::nullopt, kHeaderSize);
  for (const ChunkInfo& c : reader.chunks()) {
    checkChunk(reader, c, result);
    checkPadding(c.id, c.offset + c.storedSize);
    ++result.chunksChecked;
  }
  try {
    lightingChunks(reader);  // at most one a surface chunk
  } catch (const FileError& error) {
    result.problems.push_back({std::nullopt, error.offset().value_or(0), error.reason()});
  }
  if (reader.metadata().starts_with(kByteOrderMark))
    result.problems.push_back({std::nullopt,
                               reader.fileSize() - kTrailerSize - reader.metadata().size(),
                               "metadata starts with a byte order mark"});
  // Header, table, metadata checksum and trailer were checked when the reader opened the file.
  result.bytesChecked = bytes.size();
  return result;
}

std::string describe(const Reader& reader, const VerifyProblem& problem) {
  std::string text;
  if (problem.chunk) {
    const ChunkInfo& c = reader.chunk(*problem.chunk);
    char key[32];
    std::snprintf(key, sizeof key, "0x%llx", static_cast<unsigned long long>(c.key));
    text = "chunk " + std::to_string(c.id) + " (level " + std::to_string(c.level) + ", key " + key +
           ") at ";
  }
  return text + "byte " + std::to_string(problem.offset) + ": " + problem.reason;
}

}  // namespace iso
