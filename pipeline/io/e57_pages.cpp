// The E57 file header and checked pages (ASTM E2807 section 8.2, "Physical file structure").
#include "pipeline/io/e57_pages.h"

#include <fmt/format.h>
#include <isa-l/crc.h>

#include <algorithm>
#include <cstring>

#include "iso/check.h"
#include "pipeline/io/little_endian.h"

namespace iso::io {
namespace {

// Header fields (E2807 Table 1).
constexpr size_t kHeaderSize = 48;
constexpr size_t kVersionMajorAt = 8;
constexpr size_t kVersionMinorAt = 12;
constexpr size_t kPhysicalLengthAt = 16;
constexpr size_t kXmlPhysicalOffsetAt = 24;
constexpr size_t kXmlLogicalLengthAt = 32;
constexpr size_t kPageSizeAt = 40;

uint32_t loadBigEndian32(const std::byte* p) {
  return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | uint32_t(p[3]);
}

// CRC-32C as E57 stores it: ISA-L's crc32_iscsi leaves out the final inversion of the standard
// algorithm (RFC 3720 B.4), so it starts from all ones and the result is inverted here.
uint32_t crc32c(const std::byte* data, size_t size) {
  auto* bytes = const_cast<unsigned char*>(reinterpret_cast<const unsigned char*>(data));
  return ~crc32_iscsi(bytes, static_cast<int>(size), 0xFFFFFFFFu);
}

}  // namespace

E57Header readE57Header(InputStream& in) {
  const std::span<const std::byte> bytes = in.peek(kHeaderSize);
  if (bytes.size() < 8 || std::memcmp(bytes.data(), "ASTM-E57", 8) != 0)
    in.failAt(0, "not an E57 file: no ASTM-E57 signature");
  if (!in.knownSize())
    in.failAt(0, "gzip-compressed E57 files are not supported: decompress it first (gunzip)");
  if (bytes.size() < kHeaderSize)
    in.failAt(bytes.size(),
              fmt::format("file ends inside the 48-byte E57 header ({} bytes)", bytes.size()));
  const std::byte* p = bytes.data();
  E57Header h;
  h.versionMajor = loadLittleEndian<uint32_t>(p + kVersionMajorAt);
  h.versionMinor = loadLittleEndian<uint32_t>(p + kVersionMinorAt);
  h.physicalLength = loadLittleEndian<uint64_t>(p + kPhysicalLengthAt);
  h.xmlPhysicalOffset = loadLittleEndian<uint64_t>(p + kXmlPhysicalOffsetAt);
  h.xmlLogicalLength = loadLittleEndian<uint64_t>(p + kXmlLogicalLengthAt);
  h.pageSize = loadLittleEndian<uint64_t>(p + kPageSizeAt);
  // Minor versions add only what readers of the major version may ignore (E2807 8.2.1).
  if (h.versionMajor != 1)
    in.failAt(kVersionMajorAt, fmt::format("unsupported E57 version {}.{} (supported: 1.x)",
                                           h.versionMajor, h.versionMinor));
  if (h.pageSize < kE57MinPageSize || h.pageSize > kE57MaxPageSize || h.pageSize % 4 != 0)
    in.failAt(kPageSizeAt, fmt::format("unsupported page size {} (supported: a multiple of 4 from "
                                       "{} bytes to 1 MiB; E57 writers use 1024)",
                                       h.pageSize, kE57MinPageSize));
  const uint64_t size = *in.knownSize();
  if (size % h.pageSize != 0)
    in.failAt(size, fmt::format("the file's {} bytes are not a whole number of {}-byte pages: it "
                                "is truncated or damaged",
                                size, h.pageSize));
  if (h.physicalLength != size)
    in.failAt(kPhysicalLengthAt,
              fmt::format("the header gives the file's length as {} bytes, but it has {}: it is "
                          "truncated or damaged",
                          h.physicalLength, size));
  return h;
}

E57Pages::E57Pages(InputStream& in, const E57Header& header)
    : in_(in),
      pageSize_(header.pageSize),
      dataSize_(header.pageSize - kE57ChecksumSize),
      pageCount_(header.physicalLength / header.pageSize),
      page_(dataSize_) {
  ISO_CHECK(pageSize_ >= kE57MinPageSize && pageCount_ > 0);
  loadPage(0);  // the header's own page
}

std::optional<uint64_t> E57Pages::logicalOffset(uint64_t physical) const {
  const uint64_t page = physical / pageSize_;
  const uint64_t within = physical % pageSize_;
  if (page >= pageCount_ || within >= dataSize_) return std::nullopt;
  return page * dataSize_ + within;
}

void E57Pages::read(uint64_t logical, std::byte* out, size_t count) {
  ISO_CHECK(logical <= logicalLength() && count <= logicalLength() - logical);
  while (count > 0) {
    const uint64_t page = logical / dataSize_;
    const size_t within = static_cast<size_t>(logical % dataSize_);
    if (loadedPage_ != page) loadPage(page);
    const size_t take = std::min<size_t>(count, dataSize_ - within);
    std::memcpy(out, page_.data() + within, take);
    out += take;
    count -= take;
    logical += take;
  }
}

void E57Pages::loadPage(uint64_t page) {
  const uint64_t at = page * pageSize_;
  loadedPage_.reset();
  if (in_.offset() != at) in_.seek(at);
  const std::span<const std::byte> bytes = in_.peek(pageSize_);
  if (bytes.size() < pageSize_)
    in_.failAt(at + bytes.size(), fmt::format("file ends inside page {}", page));
  const uint32_t stored = loadBigEndian32(bytes.data() + dataSize_);
  const uint32_t computed = crc32c(bytes.data(), dataSize_);
  if (stored != computed)
    in_.failAt(at, fmt::format("page {}: CRC-32C mismatch (stored {:08x}, computed {:08x}): the "
                               "file is damaged",
                               page, stored, computed));
  std::memcpy(page_.data(), bytes.data(), dataSize_);
  in_.consume(pageSize_);
  loadedPage_ = page;
}

}  // namespace iso::io
