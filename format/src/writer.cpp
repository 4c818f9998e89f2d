// Streaming writer (specs/iso-format.md, "File layout"): header first, payloads as they come,
// chunk table, metadata and trailer last, then an atomic rename.
#include "iso/writer.h"

#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

#include "bytes.h"
#include "chunk_rules.h"
#include "iso/atomic_file.h"
#include "iso/check.h"
#include "layout.h"

namespace iso {

using detail::alignUp;

struct Writer::Impl {
  AtomicFile file;
  FileHeader header;
  WriterOptions options;
  std::vector<ChunkInfo> chunks;
  std::string metadata = "{}";
  std::vector<std::byte> compressed;
  ZSTD_CCtx* zstd = nullptr;
  bool isOpen = true;     // chunks may be added
  bool isClosed = false;  // the temporary file is complete, not yet committed
  detail::Trailer trailer;

  Impl(std::filesystem::path output, const FileHeader& h, WriterOptions o)
      : file(std::move(output)), header(h), options(o) {}
  ~Impl() { ZSTD_freeCCtx(zstd); }

  void requireOpen() const {
    if (!isOpen) throw InternalError("iso::Writer used after finish() or abandon()");
  }

  // Compress data into `compressed`; returns false when that would not make it smaller.
  bool compress(std::span<const std::byte> data) {
    if (data.empty()) return false;
    if (zstd == nullptr && (zstd = ZSTD_createCCtx()) == nullptr) throw std::bad_alloc();
    ZSTD_CCtx_reset(zstd, ZSTD_reset_session_and_parameters);
    ZSTD_CCtx_setParameter(zstd, ZSTD_c_compressionLevel, options.zstdLevel);
    ZSTD_CCtx_setParameter(zstd, ZSTD_c_contentSizeFlag, 1);
    compressed.resize(ZSTD_compressBound(data.size()));
    const size_t size =
        ZSTD_compress2(zstd, compressed.data(), compressed.size(), data.data(), data.size());
    ISO_CHECK(!ZSTD_isError(size));
    compressed.resize(size);
    return size < data.size();
  }

  // Write a chunk's stored bytes at the current position (aligned) and enter it in the table
  // (`c` has everything but its offset); returns its id.
  uint32_t append(ChunkInfo c, std::span<const std::byte> stored) {
    c.offset = file.position();
    ISO_CHECK(c.offset % header.payloadAlignment() == 0);
    requireValidEntry(c);
    file.write(stored);
    file.writeZeros(alignUp(file.position(), header.payloadAlignment()) - file.position());
    chunks.push_back(c);
    return c.id;
  }

  // Write metadata and trailer at the current position (right after the chunk table).
  void writeMetadataAndTrailer() {
    const auto bytes = std::as_bytes(std::span(metadata));
    trailer.metadataOffset = file.position();
    trailer.metadataSize = bytes.size();
    trailer.metadataChecksum = detail::checksum(bytes);
    file.write(bytes);
    file.write(detail::encodeTrailer(trailer));
    file.flush();  // a reader may open the temporary file now
  }

  // Throw unless entry c, its payload written at c.offset, follows the rules that a reader checks
  // of each entry on its own (specs/iso-format.md, "Chunk table"): the chunk table follows
  // whatever is written, so no payload can run into it.
  void requireValidEntry(const ChunkInfo& c) const {
    if (std::optional<detail::FieldProblem> problem = detail::chunkEntryProblem(
            c, c.id, header.maxLevel, c.offset, std::numeric_limits<uint64_t>::max()))
      throw InternalError(refusal(c.id, problem->reason));
  }

  // The same for the rules of the whole table (parents, the surface chunks' point counts).
  void requireValidTable() const {
    std::optional<detail::ChunkProblem> problem = detail::parentProblem(chunks);
    if (!problem) problem = detail::surfacePointCountProblem(chunks);
    if (problem) throw InternalError(refusal(problem->chunk, problem->field.reason));
  }

  static std::string refusal(uint32_t chunk, const std::string& reason) {
    return "iso::Writer: chunk " + std::to_string(chunk) + ": " + reason +
           " (a reader would refuse the file: specs/iso-format.md, \"Chunk table\")";
  }
};

Writer::Writer(std::filesystem::path output, const FileHeader& header, WriterOptions options) {
  if (header.versionMajor != kFormatMajor || header.versionMinor != kFormatMinor)
    throw InternalError("iso::Writer writes format version " +
                                std::to_string(kFormatMajor) + "." + std::to_string(kFormatMinor) +
                                " only");
  if (std::optional<detail::FieldProblem> problem = detail::headerProblem(header))
    throw InternalError("invalid .iso header: " + problem->reason);
  if (options.zstdLevel < ZSTD_minCLevel() || options.zstdLevel > ZSTD_maxCLevel())
    throw InternalError("zstd level out of range");
  impl_ = std::make_unique<Impl>(std::move(output), header, options);
  const auto encoded = detail::encodeHeader(header);
  impl_->file.write(encoded);
  impl_->file.writeZeros(alignUp(kHeaderSize, header.payloadAlignment()) - kHeaderSize);
}

Writer::~Writer() = default;
Writer::Writer(Writer&&) noexcept = default;
Writer& Writer::operator=(Writer&&) noexcept = default;

uint32_t Writer::addChunk(const ChunkDesc& desc, std::span<const std::byte> data) {
  Impl& w = *impl_;
  w.requireOpen();
  if (w.chunks.size() >= kNoParent) throw InternalError("too many chunks");

  ChunkInfo c;
  c.id = static_cast<uint32_t>(w.chunks.size());
  c.parent = desc.parent;
  c.kind = desc.kind;
  c.level = desc.level;
  c.key = desc.key;
  c.pointCount = desc.pointCount;
  c.nodeCount = desc.nodeCount;
  c.leafCount = desc.leafCount;
  c.geometricError = desc.geometricError;
  c.rawSize = data.size();
  // The description is checked as the raw entry it would be before anything is compressed (an
  // unknown codec too); append() checks the entry as it is stored.
  c.codec = desc.codec == Codec::Zstd ? Codec::Raw : desc.codec;
  c.storedSize = c.rawSize;
  c.offset = w.file.position();
  w.requireValidEntry(c);

  std::span<const std::byte> stored = data;
  if (desc.codec == Codec::Zstd && w.compress(data)) {
    stored = w.compressed;
    c.codec = Codec::Zstd;
  }
  c.storedSize = stored.size();
  c.checksum = detail::checksum(stored);
  return w.append(c, stored);
}

uint32_t Writer::copyChunk(const ChunkInfo& info, std::span<const std::byte> stored) {
  Impl& w = *impl_;
  w.requireOpen();
  if (w.chunks.size() >= kNoParent) throw InternalError("too many chunks");
  ChunkInfo c = info;
  c.id = static_cast<uint32_t>(w.chunks.size());
  c.offset = w.file.position();
  w.requireValidEntry(c);
  if (stored.size() != info.storedSize) throw InternalError("copyChunk: stored size differs");
  c.checksum = detail::checksum(stored);
  if (c.checksum != info.checksum) throw InternalError("copyChunk: the bytes are not the chunk's");
  return w.append(c, stored);
}

void Writer::setParent(uint32_t chunk, uint32_t parent) {
  impl_->requireOpen();
  if (chunk >= impl_->chunks.size()) throw InternalError("setParent: no such chunk");
  ChunkInfo c = impl_->chunks[chunk];
  c.parent = parent;
  impl_->requireValidEntry(c);  // some kinds have no parent
  impl_->chunks[chunk] = c;
}

namespace {

void requireJsonObject(const std::string& json) {
  const size_t first = json.find_first_not_of(" \t\r\n");
  const size_t last = json.find_last_not_of(" \t\r\n");
  if (first == std::string::npos || json[first] != '{' || json[last] != '}')
    throw InternalError("metadata must be a JSON object");
}

}  // namespace

void Writer::setMetadata(std::string json) {
  impl_->requireOpen();
  requireJsonObject(json);
  impl_->metadata = std::move(json);
}

void Writer::finish() {
  close();
  commit();
}

void Writer::close() {
  Impl& w = *impl_;
  w.requireOpen();
  w.requireValidTable();

  detail::Trailer& trailer = w.trailer;
  trailer.chunkTableOffset = w.file.position();
  trailer.chunkCount = static_cast<uint32_t>(w.chunks.size());
  detail::Checksummer tableChecksum;
  std::vector<std::byte> block;
  constexpr size_t kEntriesPerBlock = 1024;
  for (size_t first = 0; first < w.chunks.size(); first += kEntriesPerBlock) {
    const size_t count = std::min(kEntriesPerBlock, w.chunks.size() - first);
    block.resize(count * kChunkEntrySize);
    for (size_t i = 0; i < count; ++i)
      detail::encodeChunkEntry(w.chunks[first + i], block.data() + i * kChunkEntrySize);
    tableChecksum.update(block);
    w.file.write(block);
  }
  trailer.chunkTableChecksum = tableChecksum.digest();
  w.writeMetadataAndTrailer();
  w.isOpen = false;
  w.isClosed = true;
}

void Writer::replaceMetadata(std::string json) {
  Impl& w = *impl_;
  if (!w.isClosed) throw InternalError("iso::Writer::replaceMetadata before close()");
  requireJsonObject(json);
  w.metadata = std::move(json);
  w.file.truncate(w.trailer.metadataOffset);
  w.writeMetadataAndTrailer();
}

void Writer::commit() {
  Impl& w = *impl_;
  if (!w.isClosed) throw InternalError("iso::Writer::commit before close()");
  w.file.commit();
  w.isClosed = false;
}

void Writer::abandon() noexcept {
  if (!impl_) return;
  impl_->file.discard();
  impl_->isOpen = false;
  impl_->isClosed = false;
}

uint32_t Writer::chunkCount() const { return static_cast<uint32_t>(impl_->chunks.size()); }
uint64_t Writer::bytesWritten() const { return impl_->file.position(); }
const std::filesystem::path& Writer::temporaryPath() const { return impl_->file.temporaryPath(); }

}  // namespace iso
