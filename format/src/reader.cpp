// Reader: validation of everything but the payloads before use (specs/iso-format.md, "What readers
// check"), and the one way to a chunk's data, which checks it first: zero copy for raw payloads,
// zstd decoding once the frame is known to hold the data.
#include "iso/reader.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <vector>

#include "bytes.h"
#include "chunk_rules.h"
#include "file_io.h"
#include "iso/check.h"
#include "iso/error.h"
#include "iso/lighting.h"
#include "iso/points.h"
#include "iso/surface.h"
#include "layout.h"
#include "zstd_payload.h"

namespace iso {

using detail::alignUp;
using detail::loadLE;

namespace {

// What opening a file learns about it.
struct ParsedFile {
  FileHeader header;
  std::vector<ChunkInfo> chunks;
  uint64_t chunkTableOffset = 0;
  uint64_t metadataOffset = 0;
  uint64_t metadataSize = 0;
};

class Parser {
 public:
  Parser(const std::string& name, std::span<const std::byte> bytes)
      : name_(name), bytes_(bytes), size_(bytes.size()) {}

  ParsedFile parse() {
    if (size_ < kHeaderSize + kTrailerSize)
      fail(std::nullopt, "file is " + std::to_string(size_) +
                             " bytes, too small for an .iso file (at least 320 bytes)");
    parseHeader();
    const detail::Trailer trailer = parseTrailer();
    parseChunkTable(trailer);
    return std::move(r_);
  }

 private:
  [[noreturn]] void fail(std::optional<uint64_t> offset, const std::string& reason) const {
    throw FileError(name_, offset, reason);
  }

  void parseHeader() {
    const std::byte* p = bytes_.data();
    if (std::memcmp(p + detail::hdr::kMagic, kHeaderMagic.data(), kHeaderMagic.size()) != 0)
      fail(0, "not an .iso file (wrong magic bytes)");
    const uint16_t major = loadLE<uint16_t>(p + detail::hdr::kVersionMajor);
    const uint16_t minor = loadLE<uint16_t>(p + detail::hdr::kVersionMinor);
    if (major != kFormatMajor && major != kOldestFormatMajor)
      fail(detail::hdr::kVersionMajor, "format version " + std::to_string(major) + "." +
                                           std::to_string(minor) +
                                           " is not supported (this reader reads versions " +
                                           std::to_string(kOldestFormatMajor) + ".x to " +
                                           std::to_string(kFormatMajor) + ".x)");
    const uint32_t headerSize = loadLE<uint32_t>(p + detail::hdr::kHeaderSize);
    if (headerSize != kHeaderSize)
      fail(detail::hdr::kHeaderSize,
           "header size is " + std::to_string(headerSize) + ", expected 256");
    if (loadLE<uint64_t>(p + detail::hdr::kChecksum) !=
        detail::checksum({p, detail::hdr::kChecksum}))
      fail(detail::hdr::kChecksum, "header checksum mismatch (the header is corrupt)");
    std::optional<detail::FieldProblem> problem;
    r_.header = detail::decodeHeader(p, problem);
    if (problem) fail(problem->offset, "header: " + problem->reason);
  }

  detail::Trailer parseTrailer() {
    const uint64_t at = size_ - kTrailerSize;
    const std::byte* p = bytes_.data() + at;
    if (std::memcmp(p + detail::trl::kMagic, kTrailerMagic.data(), kTrailerMagic.size()) != 0)
      fail(
          at + detail::trl::kMagic,
          "no trailer at the end of the file: the file is truncated or was not completely written");
    if (loadLE<uint64_t>(p + detail::trl::kChecksum) !=
        detail::checksum({p, detail::trl::kChecksum}))
      fail(at + detail::trl::kChecksum, "trailer checksum mismatch (the trailer is corrupt)");
    const detail::Trailer t = detail::decodeTrailer(p);
    if (t.chunkEntrySize != kChunkEntrySize)
      fail(at + detail::trl::kChunkEntrySize,
           "chunk entry size is " + std::to_string(t.chunkEntrySize) + ", expected 80");

    const uint64_t alignment = r_.header.payloadAlignment();
    const uint64_t firstPayload = alignUp(kHeaderSize, alignment);
    if (t.chunkTableOffset > at || t.chunkTableOffset < firstPayload ||
        t.chunkTableOffset % alignment != 0)
      fail(at + detail::trl::kChunkTableOffset, "chunk table offset " +
                                                    std::to_string(t.chunkTableOffset) +
                                                    " is outside the file or not aligned");
    const uint64_t tableBytes = uint64_t{t.chunkCount} * kChunkEntrySize;
    if (tableBytes > at - t.chunkTableOffset || t.metadataOffset != t.chunkTableOffset + tableBytes)
      fail(at + detail::trl::kMetadataOffset,
           "chunk table of " + std::to_string(t.chunkCount) + " entries does not fit before the " +
               "metadata (metadata offset " + std::to_string(t.metadataOffset) + ")");
    if (t.metadataSize != at - t.metadataOffset)
      fail(at + detail::trl::kMetadataSize,
           "metadata size " + std::to_string(t.metadataSize) + " does not reach the trailer");

    if (detail::checksum(bytes_.subspan(t.chunkTableOffset, tableBytes)) != t.chunkTableChecksum)
      fail(t.chunkTableOffset, "chunk table checksum mismatch (the chunk table is corrupt)");
    if (detail::checksum(bytes_.subspan(t.metadataOffset, t.metadataSize)) != t.metadataChecksum)
      fail(t.metadataOffset, "metadata checksum mismatch (the metadata is corrupt)");
    r_.chunkTableOffset = t.chunkTableOffset;
    r_.metadataOffset = t.metadataOffset;
    r_.metadataSize = t.metadataSize;
    return t;
  }

  void parseChunkTable(const detail::Trailer& t) {
    const uint64_t alignment = r_.header.payloadAlignment();
    uint64_t expected = alignUp(kHeaderSize, alignment);
    r_.chunks.resize(t.chunkCount);
    for (uint32_t i = 0; i < t.chunkCount; ++i) {
      const uint64_t at = t.chunkTableOffset + uint64_t{i} * kChunkEntrySize;
      std::optional<uint32_t> reserved;
      const ChunkInfo c = detail::decodeChunkEntry(bytes_.data() + at, reserved);
      if (reserved)
        fail(at + *reserved, "chunk " + std::to_string(i) + ": reserved field is not zero");
      if (std::optional<detail::FieldProblem> problem =
              detail::chunkEntryProblem(c, i, r_.header.maxLevel, expected, t.chunkTableOffset))
        fail(at + problem->offset, "chunk " + std::to_string(i) + ": " + problem->reason);
      expected = alignUp(c.offset + c.storedSize, alignment);
      r_.chunks[i] = c;
    }
    if (expected != t.chunkTableOffset)
      fail(t.chunkTableOffset, "chunk table does not follow the last payload (expected at byte " +
                                   std::to_string(expected) + ")");
    if (std::optional<detail::ChunkProblem> problem = detail::parentProblem(r_.chunks))
      failEntry(t.chunkTableOffset, *problem);
    if (std::optional<detail::ChunkProblem> problem = detail::surfacePointCountProblem(r_.chunks))
      failEntry(t.chunkTableOffset, *problem);
  }

  [[noreturn]] void failEntry(uint64_t tableOffset, const detail::ChunkProblem& problem) const {
    fail(tableOffset + uint64_t{problem.chunk} * kChunkEntrySize + problem.field.offset,
         "chunk " + std::to_string(problem.chunk) + ": " + problem.field.reason);
  }

  const std::string& name_;
  ParsedFile r_;
  std::span<const std::byte> bytes_;
  uint64_t size_;
};

}  // namespace

struct Reader::Impl {
  std::string name;
  std::unique_ptr<detail::MappedFile> mapping;
  std::span<const std::byte> bytes;
  ParsedFile file;
};

Reader::Reader(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}

Reader Reader::open(const std::filesystem::path& path) {
  auto impl = std::make_shared<Impl>();
  impl->name = path.string();
  impl->mapping = std::make_unique<detail::MappedFile>(path);
  impl->bytes = impl->mapping->bytes();
  impl->file = Parser(impl->name, impl->bytes).parse();
  return Reader(std::move(impl));
}

Reader Reader::fromMemory(std::span<const std::byte> bytes, std::string name) {
  auto impl = std::make_shared<Impl>();
  impl->name = std::move(name);
  impl->bytes = bytes;
  impl->file = Parser(impl->name, impl->bytes).parse();
  return Reader(std::move(impl));
}

const std::string& Reader::name() const { return impl_->name; }
uint64_t Reader::fileSize() const { return impl_->bytes.size(); }
const FileHeader& Reader::header() const { return impl_->file.header; }
std::span<const ChunkInfo> Reader::chunks() const { return impl_->file.chunks; }
std::span<const std::byte> Reader::bytes() const { return impl_->bytes; }

const ChunkInfo& Reader::chunk(uint32_t id) const {
  if (id >= impl_->file.chunks.size()) throw std::out_of_range("no chunk " + std::to_string(id));
  return impl_->file.chunks[id];
}

std::string_view Reader::metadata() const {
  const auto m = impl_->bytes.subspan(impl_->file.metadataOffset, impl_->file.metadataSize);
  return {reinterpret_cast<const char*>(m.data()), m.size()};
}

namespace {

[[noreturn]] void failChunk(const Reader& reader, uint32_t id, const std::string& reason) {
  throw FileError(reader.name(), reader.chunk(id).offset,
                  "chunk " + std::to_string(id) + ": " + reason);
}

// A chunk's stored bytes, checked against its checksum and, for zstd, against its raw size (the
// frame's content size, its blocks' capacity): before anything is decoded or allocated.
std::span<const std::byte> checkedStoredBytes(const Reader& reader, uint32_t id) {
  const ChunkInfo& c = reader.chunk(id);
  const std::span<const std::byte> stored = reader.bytes().subspan(c.offset, c.storedSize);
  if (const uint64_t computed = detail::checksum(stored); computed != c.checksum) {
    char values[64];
    std::snprintf(values, sizeof values, " (table 0x%016llx, payload 0x%016llx)",
                  static_cast<unsigned long long>(c.checksum),
                  static_cast<unsigned long long>(computed));
    failChunk(reader, id, std::string("checksum mismatch") + values);
  }
  if (c.codec == Codec::Zstd)
    if (std::string problem = detail::zstdFrameProblem(stored, c.rawSize); !problem.empty())
      failChunk(reader, id, problem);
  return stored;
}

}  // namespace

ChunkData Reader::payload(uint32_t id) const {
  const std::span<const std::byte> stored = checkedStoredBytes(*this, id);
  if (chunk(id).codec == Codec::Raw) return ChunkData(stored);
  std::vector<std::byte> data(chunk(id).rawSize);
  if (std::string problem = detail::zstdDecodeProblem(stored, data); !problem.empty())
    failChunk(*this, id, problem);
  return ChunkData(std::move(data));
}

void Reader::decodePayload(uint32_t id, std::span<std::byte> out) const {
  const ChunkInfo& c = chunk(id);
  if (out.size() < c.rawSize)
    throw InternalError("decodePayload: output buffer smaller than the chunk's raw size");
  const std::span<const std::byte> stored = checkedStoredBytes(*this, id);
  if (c.codec == Codec::Raw) {
    if (!stored.empty()) std::memcpy(out.data(), stored.data(), stored.size());
    return;
  }
  if (std::string problem = detail::zstdDecodeProblem(stored, out.first(c.rawSize));
      !problem.empty())
    failChunk(*this, id, problem);
}

void Reader::checkPayload(uint32_t id) const {
  const std::span<const std::byte> stored = checkedStoredBytes(*this, id);
  if (chunk(id).codec == Codec::Zstd)
    if (std::string problem = detail::zstdStreamProblem(stored, chunk(id).rawSize);
        !problem.empty())
      failChunk(*this, id, problem);
}

}  // namespace iso
