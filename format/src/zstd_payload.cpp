// zstd payloads: frame and block headers read before decoding (RFC 8878, 3.1.1), decoding with a
// context per thread, and a streaming check.
#include "zstd_payload.h"

#define ZSTD_STATIC_LINKING_ONLY  // ZSTD_getFrameHeader: the header's block size limit
#include <zstd.h>

#include <memory>
#include <new>
#include <optional>
#include <vector>

namespace iso::detail {
namespace {

// The most bytes the blocks of a frame can decode to: a Raw or RLE block its Block_Size, a
// Compressed block the frame's Block_Maximum_Size (RFC 8878, 3.1.1.2). nullopt when the block
// headers do not end with a last block inside the stored bytes.
std::optional<uint64_t> blockCapacity(std::span<const std::byte> stored,
                                      const ZSTD_frameHeader& frame) {
  enum : uint32_t { kRaw = 0, kRle = 1, kCompressed = 2 };
  uint64_t at = frame.headerSize, capacity = 0;
  while (stored.size() - at >= 3) {
    const uint32_t header =
        uint32_t(stored[at]) | uint32_t(stored[at + 1]) << 8 | uint32_t(stored[at + 2]) << 16;
    const uint32_t type = (header >> 1) & 3, size = header >> 3;
    if (type > kCompressed) return std::nullopt;  // reserved block type
    const uint64_t content = type == kRle ? 1 : size;
    at += 3;
    if (stored.size() - at < content) return std::nullopt;
    at += content;
    capacity += type == kCompressed ? frame.blockSizeMax : size;
    if ((header & 1) != 0) return capacity;  // Last_Block
  }
  return std::nullopt;
}

// A zstd decompression context per thread, so that const Reader calls can run concurrently.
ZSTD_DCtx* threadDecompressor() {
  struct Holder {
    ZSTD_DCtx* context = ZSTD_createDCtx();
    ~Holder() { ZSTD_freeDCtx(context); }
  };
  thread_local Holder holder;
  if (holder.context == nullptr) throw std::bad_alloc();
  return holder.context;
}

}  // namespace

std::string zstdFrameProblem(std::span<const std::byte> stored, uint64_t rawSize) {
  ZSTD_frameHeader frame{};
  const size_t missing = ZSTD_getFrameHeader(&frame, stored.data(), stored.size());
  if (ZSTD_isError(missing) || missing != 0 || frame.frameType != ZSTD_frame)
    return "zstd payload does not start with a zstd frame header";
  if (frame.frameContentSize != rawSize)
    return "zstd frame content size differs from the chunk's raw size";
  if (ZSTD_findFrameCompressedSize(stored.data(), stored.size()) != stored.size())
    return "zstd payload is not exactly one complete frame";
  const std::optional<uint64_t> capacity = blockCapacity(stored, frame);
  if (!capacity) return "zstd payload is not exactly one complete frame";
  if (*capacity < rawSize)
    return "zstd frame's blocks hold at most " + std::to_string(*capacity) +
           " bytes, less than its content size " + std::to_string(rawSize);
  return {};
}

std::string zstdDecodeProblem(std::span<const std::byte> stored, std::span<std::byte> out) {
  const size_t decoded = ZSTD_decompressDCtx(threadDecompressor(), out.data(), out.size(),
                                             stored.data(), stored.size());
  if (ZSTD_isError(decoded)) return std::string("zstd: ") + ZSTD_getErrorName(decoded);
  if (decoded != out.size())
    return "zstd payload decodes to " + std::to_string(decoded) + " bytes, expected " +
           std::to_string(out.size());
  return {};
}

std::string zstdStreamProblem(std::span<const std::byte> stored, uint64_t rawSize) {
  struct Stream {
    std::unique_ptr<ZSTD_DStream, size_t (*)(ZSTD_DStream*)> stream{ZSTD_createDStream(),
                                                                    ZSTD_freeDStream};
    std::vector<std::byte> buffer = std::vector<std::byte>(ZSTD_DStreamOutSize());
  };
  thread_local Stream s;  // reused: its buffers are large next to small files
  if (!s.stream) throw std::bad_alloc();
  ZSTD_DCtx_reset(s.stream.get(), ZSTD_reset_session_only);
  ZSTD_inBuffer in{stored.data(), stored.size(), 0};
  uint64_t produced = 0;
  size_t remaining = 1;
  while (remaining != 0) {
    ZSTD_outBuffer out{s.buffer.data(), s.buffer.size(), 0};
    const size_t consumedBefore = in.pos;
    remaining = ZSTD_decompressStream(s.stream.get(), &out, &in);
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

}  // namespace iso::detail
