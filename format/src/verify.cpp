// Verification of the bytes Reader::open does not check (specs/iso-format.md, "What readers
// check"): payload checksums, zstd streams, padding.
#include "iso/verify.h"

#include <zstd.h>

#include <cstdio>
#include <memory>
#include <vector>

#include "bytes.h"
#include "iso/error.h"
#include "iso/points.h"
#include "iso/surface.h"

namespace iso {
namespace {

// The offset of the first non-zero byte in [begin, end), if any.
std::optional<uint64_t> firstNonZero(std::span<const std::byte> bytes, uint64_t begin,
                                     uint64_t end) {
  for (uint64_t i = begin; i < end; ++i)
    if (bytes[i] != std::byte{0}) return i;
  return std::nullopt;
}

// Why a zstd payload does not decode to exactly rawSize bytes, or empty when it does. Streams
// through a small buffer, so verifying needs little memory however large the chunk.
class ZstdChecker {
 public:
  ZstdChecker() : stream_(ZSTD_createDStream(), ZSTD_freeDStream), buffer_(ZSTD_DStreamOutSize()) {
    if (!stream_) throw std::bad_alloc();
  }
  std::string problem(std::span<const std::byte> stored, uint64_t rawSize);

 private:
  std::unique_ptr<ZSTD_DStream, size_t (*)(ZSTD_DStream*)> stream_;
  std::vector<std::byte> buffer_;
};

std::string ZstdChecker::problem(std::span<const std::byte> stored, uint64_t rawSize) {
  if (ZSTD_getFrameContentSize(stored.data(), stored.size()) != rawSize)
    return "zstd frame content size differs from the chunk's raw size";
  ZSTD_DCtx_reset(stream_.get(), ZSTD_reset_session_only);
  ZSTD_inBuffer in{stored.data(), stored.size(), 0};
  uint64_t produced = 0;
  size_t remaining = 1;
  while (remaining != 0) {
    ZSTD_outBuffer out{buffer_.data(), buffer_.size(), 0};
    const size_t consumedBefore = in.pos;
    remaining = ZSTD_decompressStream(stream_.get(), &out, &in);
    if (ZSTD_isError(remaining)) return std::string("zstd: ") + ZSTD_getErrorName(remaining);
    produced += out.pos;
    if (produced > rawSize) return "zstd payload decodes to more than the chunk's raw size";
    if (remaining != 0 && out.pos < out.size && (in.pos == in.size || in.pos == consumedBefore))
      return "zstd payload ends before its frame is complete";
  }
  if (in.pos != in.size) return "zstd payload has bytes after its frame";
  if (produced != rawSize) return "zstd payload decodes to fewer bytes than the chunk's raw size";
  return {};
}

// Whether a surface or points chunk's data follows the rules of specs/iso-format.md ("Surface
// chunks", "Points chunks"); chunks of other kinds have no rules beyond their payload.
void checkContent(const Reader& reader, const ChunkInfo& c, VerifyResult& result) {
  try {
    if (c.kind == kSurfaceKind) decodeSurfaceChunk(reader, c.id);
    if (c.kind == kPointsKind) decodePointsChunk(reader, c.id);
  } catch (const FileError& error) {
    result.problems.push_back({c.id, c.offset, error.reason()});
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
  thread_local ZstdChecker zstd;  // reused: its buffers are large next to small files
  for (const ChunkInfo& c : reader.chunks()) {
    const std::span<const std::byte> stored = reader.storedPayload(c.id);
    const uint64_t computed = detail::checksum(stored);
    if (computed != c.checksum) {
      char reason[96];
      std::snprintf(reason, sizeof reason, "checksum mismatch (table 0x%016llx, payload 0x%016llx)",
                    static_cast<unsigned long long>(c.checksum),
                    static_cast<unsigned long long>(computed));
      result.problems.push_back({c.id, c.offset, reason});
    } else if (c.codec == Codec::Zstd) {
      if (std::string problem = zstd.problem(stored, c.rawSize); !problem.empty())
        result.problems.push_back({c.id, c.offset, problem});
      else
        checkContent(reader, c, result);
    } else {
      checkContent(reader, c, result);
    }
    checkPadding(c.id, c.offset + c.storedSize);
    ++result.chunksChecked;
  }
  // Header, table, metadata and trailer were checked when the reader opened the file.
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
