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

  // The first rule of the chunk table (specs/iso-format.md) that entry c breaks, as the offset of
  // the field in the entry and the reason; `expectedOffset` is where the layout puts its payload.
  std::optional<detail::FieldProblem> entryProblem(const ChunkInfo& c, uint32_t index,
                                                   uint64_t expectedOffset) const {
    namespace e = detail::entry;
    if (c.id != index) return detail::FieldProblem{e::kId, "id is " + std::to_string(c.id)};
    if (c.codec != Codec::Raw && c.codec != Codec::Zstd)
      return detail::FieldProblem{e::kCodec, "unknown codec " + std::to_string(int(c.codec))};
    if (c.level > r_.header.maxLevel)
      return detail::FieldProblem{e::kLevel, "level " + std::to_string(c.level) +
                                                 " is above the file's maximum level " +
                                                 std::to_string(r_.header.maxLevel)};
    if (!isValidKey(c.level, c.key))
      return detail::FieldProblem{e::kKey, "key does not fit its level"};
    if (c.rawSize > kMaxChunkRawSize)
      return detail::FieldProblem{e::kRawSize, "raw size is over the limit of 2^30 bytes"};
    if (c.codec == Codec::Raw && c.storedSize != c.rawSize)
      return detail::FieldProblem{e::kStoredSize, "raw chunk with stored size != raw size"};
    if (c.codec == Codec::Zstd && c.storedSize == 0)
      return detail::FieldProblem{e::kStoredSize, "zstd chunk with no stored bytes"};
    if (c.codec == Codec::Zstd && (c.rawSize + kMaxZstdRatio - 1) / kMaxZstdRatio > c.storedSize)
      return detail::FieldProblem{e::kRawSize,
                                  "raw size is more than 32768 times the stored size (more than "
                                  "a zstd frame of that size decodes to)"};
    if (c.offset != expectedOffset)
      return detail::FieldProblem{e::kOffset, "payload offset " + std::to_string(c.offset) +
                                                  " is not where the layout puts it (" +
                                                  std::to_string(expectedOffset) + ")"};
    if (c.storedSize > r_.chunkTableOffset - c.offset)
      return detail::FieldProblem{e::kStoredSize, "payload runs into the chunk table"};
    if (!std::isfinite(c.geometricError) || c.geometricError < 0.0f)
      return detail::FieldProblem{e::kGeometricError, "geometric error is negative or not finite"};
    if (c.kind == kPointsKind || c.kind == kVolumePointsKind || c.kind == kValuesKind)
      return pointsEntryProblem(c);
    if (c.kind == kLightingKind) return lightingEntryProblem(c);
    return std::nullopt;
  }

  // The rule of "Points chunks" (and, since 2.1, of "Volume points" and "Values chunks") that the
  // entry of such a chunk breaks.
  static std::optional<detail::FieldProblem> pointsEntryProblem(const ChunkInfo& c) {
    namespace e = detail::entry;
    const std::string what(c.kind == kValuesKind ? "a values chunk" : "a points chunk");
    if (c.pointCount == 0 || c.pointCount > kMaxPointsPerChunk)
      return detail::FieldProblem{e::kPointCount,
                                  what + " holds 1 to " + std::to_string(kMaxPointsPerChunk) +
                                      " points, not " + std::to_string(c.pointCount)};
    if (c.nodeCount != 0) return detail::FieldProblem{e::kNodeCount, what + " has nodes"};
    if (c.leafCount != 0) return detail::FieldProblem{e::kLeafCount, what + " has leaves"};
    if (c.kind != kPointsKind && c.parent != kNoParent)
      return detail::FieldProblem{e::kParent, what + " of this kind has no parent"};
    return std::nullopt;
  }

  // The rule of "Lighting chunks" (since 2.2) that the entry of such a chunk breaks.
  static std::optional<detail::FieldProblem> lightingEntryProblem(const ChunkInfo& c) {
    namespace e = detail::entry;
    if (c.pointCount != 0) return detail::FieldProblem{e::kPointCount, "a lighting chunk has points"};
    if (c.nodeCount != 0) return detail::FieldProblem{e::kNodeCount, "a lighting chunk has nodes"};
    if (c.leafCount != 0) return detail::FieldProblem{e::kLeafCount, "a lighting chunk has leaves"};
    if (c.parent != kNoParent)
      return detail::FieldProblem{e::kParent, "a lighting chunk has no parent"};
    if (c.geometricError != 0.0f)
      return detail::FieldProblem{e::kGeometricError, "a lighting chunk has no geometric error"};
    return std::nullopt;
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
      if (std::optional<detail::FieldProblem> problem = entryProblem(c, i, expected))
        fail(at + problem->offset, "chunk " + std::to_string(i) + ": " + problem->reason);
      expected = alignUp(c.offset + c.storedSize, alignment);
      r_.chunks[i] = c;
    }
    if (expected != t.chunkTableOffset)
      fail(t.chunkTableOffset, "chunk table does not follow the last payload (expected at byte " +
                                   std::to_string(expected) + ")");
    for (const ChunkInfo& c : r_.chunks) {
      if (c.parent == kNoParent) continue;
      const uint64_t at =
          t.chunkTableOffset + uint64_t{c.id} * kChunkEntrySize + detail::entry::kParent;
      const std::string who =
          "chunk " + std::to_string(c.id) + ": parent " + std::to_string(c.parent);
      if (c.parent >= r_.chunks.size()) fail(at, who + " does not exist");
      const ChunkInfo& p = r_.chunks[c.parent];
      if (p.level >= c.level || !cellContains(p.level, p.key, c.level, c.key))
        fail(at, who + " is not a coarser cell containing it");
      if (c.kind == kPointsKind && p.kind != kPointsKind)
        fail(at, who + " is not a points chunk (a points chunk's parent is its subsample)");
    }
    checkSurfacePointCounts(t.chunkTableOffset);
  }

  // The input points of surface chunks: those whose parent is a surface chunk count together at
  // most their parent's points (their cells are disjoint parts of its cells); the others count
  // together at most kMaxPointCount. Every sum over surface chunks then stays below 2^58.
  void checkSurfacePointCounts(uint64_t tableOffset) const {
    std::vector<uint64_t> children(r_.chunks.size(), 0);
    uint64_t tops = 0;
    for (const ChunkInfo& c : r_.chunks) {
      if (c.kind != kSurfaceKind) continue;
      const uint64_t at =
          tableOffset + uint64_t{c.id} * kChunkEntrySize + detail::entry::kPointCount;
      const std::string who =
          "chunk " + std::to_string(c.id) + ": point count " + std::to_string(c.pointCount);
      if (c.parent != kNoParent && r_.chunks[c.parent].kind == kSurfaceKind) {
        const ChunkInfo& p = r_.chunks[c.parent];
        if (c.pointCount > p.pointCount - children[p.id])
          fail(at, who + " and those of the other chunks of parent " + std::to_string(p.id) +
                       " exceed its " + std::to_string(p.pointCount));
        children[p.id] += c.pointCount;
      } else {
        if (c.pointCount > kMaxPointCount - tops)
          fail(at, who + " brings the points of the top surface chunks over 2^53");
        tops += c.pointCount;
      }
    }
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
