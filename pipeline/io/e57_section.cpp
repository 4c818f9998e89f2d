// CompressedVector binary sections and their packets (ASTM E2807 9.9.3, Tables 27–31).
#include "pipeline/io/e57_section.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <span>

#include "base/text.h"
#include "pipeline/io/little_endian.h"

namespace iso::io {
namespace {

// Section header (Table 27).
constexpr size_t kSectionHeaderSize = 32;
constexpr uint8_t kCompressedVectorSectionId = 1;
constexpr size_t kSectionLengthAt = 8;
constexpr size_t kDataOffsetAt = 16;

// Packet headers (Tables 28–31): type, a byte of flags or reserved, the packet's length minus 1;
// a data packet then has its bytestream count and a 16-bit buffer length per bytestream.
constexpr size_t kPacketHeaderSize = 4;
constexpr size_t kDataHeaderSize = 6;
constexpr uint8_t kIndexPacket = 0;
constexpr uint8_t kDataPacket = 1;
constexpr uint8_t kEmptyPacket = 2;

uint64_t bitsPerRecord(const E57Scan& scan) {
  uint64_t bits = 0;
  for (const E57Field& field : scan.prototype) bits += field.bitWidth();
  return bits;
}

}  // namespace

E57Section readE57Section(E57Pages& pages, const E57Scan& scan, const std::string& label) {
  InputStream& in = pages.stream();
  const std::optional<uint64_t> begin = pages.logicalOffset(scan.fileOffset);
  if (!begin)
    in.failAt(scan.fileOffset, fmt::format("{}: its points' fileOffset {} is past the end of the "
                                           "file or inside a page checksum",
                                           label, scan.fileOffset));
  const auto fail = [&](const std::string& reason) {
    in.failAt(scan.fileOffset, label + ": " + reason);
  };
  if (pages.logicalLength() - *begin < kSectionHeaderSize)
    fail("its section header runs past the end of the file");
  std::array<std::byte, kSectionHeaderSize> header{};
  pages.read(*begin, header.data(), header.size());
  if (uint8_t(header[0]) != kCompressedVectorSectionId)
    fail(fmt::format("its points' section has id {}, not {} (CompressedVector)", uint8_t(header[0]),
                     kCompressedVectorSectionId));
  const uint64_t length = loadLittleEndian<uint64_t>(header.data() + kSectionLengthAt);
  const uint64_t dataOffset = loadLittleEndian<uint64_t>(header.data() + kDataOffsetAt);
  if (length < kSectionHeaderSize || length > pages.logicalLength() - *begin)
    fail(fmt::format("its section's length {} is {}", length,
                     length < kSectionHeaderSize ? "shorter than the section header"
                                                 : "past the end of the file"));
  E57Section section{.begin = *begin, .end = *begin + length};
  const std::optional<uint64_t> data = pages.logicalOffset(dataOffset);
  if (!data || *data < section.begin + kSectionHeaderSize || *data > section.end)
    fail(fmt::format("its first data packet's offset {} lies outside its section", dataOffset));
  section.dataBegin = *data;
  const uint64_t bits = bitsPerRecord(scan);
  if (bits == 0)
    fail(
        "every field of its prototype is constant (0 bits per record), which this reader does not "
        "support");
  const uint64_t capacity = (section.end - section.dataBegin) * 8 / bits;
  if (scan.recordCount > capacity)
    fail(fmt::format("its section's {} bytes cannot hold {} records of {} bits", length,
                     withSeparators(scan.recordCount), bits));
  return section;
}

E57PacketReader::E57PacketReader(E57Pages& pages, const E57Section& section, const E57Scan& scan,
                                 std::string label)
    : pages_(pages),
      section_(section),
      scan_(scan),
      label_(std::move(label)),
      next_(section.dataBegin) {
  streams_.reserve(scan.prototype.size());
  for (const E57Field& field : scan.prototype) streams_.emplace_back(field);
}

void E57PacketReader::failAt(uint64_t logical, const std::string& reason) const {
  pages_.stream().failAt(pages_.physicalOffset(logical), label_ + ": " + reason);
}

bool E57PacketReader::readPacket() {
  const uint64_t at = next_;
  if (at == section_.end) return false;
  if (section_.end - at < kPacketHeaderSize)
    failAt(at, "a packet header crosses the end of its section");
  std::array<std::byte, kPacketHeaderSize> header{};
  pages_.read(at, header.data(), header.size());
  const auto type = uint8_t(header[0]);
  const uint64_t length = uint64_t{loadLittleEndian<uint16_t>(header.data() + 2)} + 1;
  if (type != kIndexPacket && type != kDataPacket && type != kEmptyPacket)
    failAt(at, fmt::format("unknown packet type {} (known: 0 index, 1 data, 2 empty)", type));
  if (length % 4 != 0)
    failAt(at, fmt::format("a packet's length {} is not a multiple of 4", length));
  if (length > section_.end - at)
    failAt(at, fmt::format("a packet of {} bytes runs past the end of its section (byte {})",
                           length, pages_.physicalOffset(section_.end)));
  if (type == kDataPacket) readDataPacket(at, static_cast<size_t>(length));
  next_ = at + length;
  return true;
}

void E57PacketReader::readDataPacket(uint64_t at, size_t length) {
  if (length < kDataHeaderSize)
    failAt(at, fmt::format("a data packet of {} bytes is shorter than its header", length));
  packet_.resize(length);
  pages_.read(at, packet_.data(), length);
  const size_t count = loadLittleEndian<uint16_t>(packet_.data() + 4);
  if (count != streams_.size())
    failAt(at, fmt::format("a data packet has {} bytestreams, but the prototype has {} fields",
                           count, streams_.size()));
  size_t buffer = kDataHeaderSize + 2 * count;
  if (buffer > length)
    failAt(at,
           fmt::format("a data packet's {} buffer lengths run past its {} bytes", count, length));
  for (size_t i = 0; i < count; ++i) {
    const size_t size = loadLittleEndian<uint16_t>(packet_.data() + kDataHeaderSize + 2 * i);
    if (size > length - buffer)
      failAt(at, fmt::format("the buffer of bytestream {} ('{}', {} bytes) runs past the end of "
                             "its {}-byte data packet",
                             i, scan_.prototype[i].name, size, length));
    streams_[i].append(std::span(packet_).subspan(buffer, size));
    buffer += size;
  }
  checkPendingBytes(at);
}

void E57PacketReader::checkPendingBytes(uint64_t at) const {
  size_t pending = 0;
  size_t largest = 0;
  for (size_t i = 0; i < streams_.size(); ++i) {
    pending += streams_[i].pendingBytes();
    if (streams_[i].pendingBytes() > streams_[largest].pendingBytes()) largest = i;
  }
  if (pending > kE57MaxPendingBytes)
    failAt(at,
           fmt::format("field '{}' has {} of values waiting for the other fields' (more than "
                       "the {} held for all fields): its packets do not interleave the fields",
                       scan_.prototype[largest].name, byteSize(streams_[largest].pendingBytes()),
                       byteSize(kE57MaxPendingBytes)));
}

}  // namespace iso::io
