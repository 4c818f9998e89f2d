#include "pipeline/io/laz_chunks.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <limits>
#include <string>

#include "pipeline/io/laz_coder.h"
#include "pipeline/io/laz_decoder.h"
#include "pipeline/io/little_endian.h"

namespace iso::io {
namespace {

// The LASzip VLR (LASzip's laszip_dll.cpp, laz-perf's vlr.cpp): compressor u16, coder u16,
// version major u8, minor u8, revision u16, options u32, chunk size u32, number and offset of
// special EVLRs (i64 each), number of items u16, then each item's type, size and version (u16).
constexpr size_t kCompressorAt = 0;
constexpr size_t kCoderAt = 2;
constexpr size_t kChunkSizeAt = 12;
constexpr size_t kItemCountAt = 32;
constexpr size_t kItemsAt = 34;
constexpr size_t kItemBytes = 6;

enum Compressor : uint16_t {
  kNone = 0,
  kPointwise = 1,
  kPointwiseChunked = 2,
  kLayeredChunked = 3
};

// Item types and the versions laz-perf decodes: version 2 of the LAS 1.0–1.3 items, version 3 of
// the LAS 1.4 ones.
enum ItemType : uint16_t {
  kByte = 0,
  kPoint10 = 6,
  kGpsTime11 = 7,
  kRgb12 = 8,
  kWavepacket13 = 9,
  kPoint14 = 10,
  kRgb14 = 11,
  kRgbNir14 = 12,
  kWavepacket14 = 13,
  kByte14 = 14
};

struct Item {
  uint16_t type, size, version;
};

std::string itemName(uint16_t type) {
  switch (type) {
    case kByte:
      return "BYTE";
    case kPoint10:
      return "POINT10";
    case kGpsTime11:
      return "GPSTIME11";
    case kRgb12:
      return "RGB12";
    case kWavepacket13:
      return "WAVEPACKET13";
    case kPoint14:
      return "POINT14";
    case kRgb14:
      return "RGB14";
    case kRgbNir14:
      return "RGBNIR14";
    case kWavepacket14:
      return "WAVEPACKET14";
    case kByte14:
      return "BYTE14";
    default:
      return fmt::format("of type {}", type);
  }
}

// The items laz-perf's ChunkDecoder decodes for a point format with `extraBytes` extra bytes.
std::vector<Item> expectedItems(int format, uint16_t extraBytes) {
  std::vector<Item> items;
  if (format <= 3) {
    items.push_back({kPoint10, 20, 2});
    if (format == 1 || format == 3) items.push_back({kGpsTime11, 8, 2});
    if (format == 2 || format == 3) items.push_back({kRgb12, 6, 2});
    if (extraBytes > 0) items.push_back({kByte, extraBytes, 2});
  } else {
    items.push_back({kPoint14, 30, 3});
    if (format == 7) items.push_back({kRgb14, 6, 3});
    if (format == 8) items.push_back({kRgbNir14, 8, 3});
    if (extraBytes > 0) items.push_back({kByte14, extraBytes, 3});
  }
  return items;
}

constexpr uint16_t kStandardRecord[9] = {20, 28, 26, 34, 57, 63, 30, 36, 38};

// At most this many chunks (the table of 2^24 takes 400 MiB; LASzip's default 50,000 points a
// chunk puts 800 billion points in them).
constexpr uint64_t kMaxChunks = uint64_t{1} << 24;

// The bytes of the chunk table, read from the stream up to a limit (then zeros, noted).
class TableBytes {
 public:
  TableBytes(InputStream& in, uint64_t limit) : in_(in), limit_(limit) {}
  uint32_t next() {
    if (read_ < limit_) {
      const std::span<const std::byte> bytes = in_.peek(1);
      if (!bytes.empty()) {
        ++read_;
        in_.consume(1);
        return uint32_t(bytes[0]);
      }
    }
    isOverrun_ = true;
    return 0;
  }
  // Whether the decoder needed bytes past the end of the table.
  bool isOverrun() const { return isOverrun_; }

 private:
  InputStream& in_;
  uint64_t limit_, read_ = 0;
  bool isOverrun_ = false;
};

// Where the chunk table starts: the offset at the start of the point data, or, when that is −1
// (a writer that could not seek back), the file's last 8 bytes.
uint64_t chunkTableOffset(InputStream& in, const LasHeader& header, uint64_t fileSize) {
  const uint64_t firstChunk = header.pointDataOffset + 8;
  std::array<std::byte, 8> bytes{};
  in.seek(header.pointDataOffset);
  if (!in.readExact(bytes.data(), 8))
    in.fail("file ends before the chunk table's offset at the start of the point data");
  int64_t offset = loadLittleEndian<int64_t>(bytes.data());
  if (offset == -1) {
    if (fileSize < firstChunk + 8) in.failAt(fileSize, "file ends before the chunk table's offset");
    in.seek(fileSize - 8);
    if (!in.readExact(bytes.data(), 8)) in.fail("cannot read the chunk table's offset");
    offset = loadLittleEndian<int64_t>(bytes.data());
  }
  if (offset < 0 || uint64_t(offset) < firstChunk || uint64_t(offset) + 8 > fileSize)
    in.failAt(header.pointDataOffset,
              fmt::format("damaged chunk table: its offset {} lies outside the {} bytes from the "
                          "first chunk (byte {}) to the end of the file (the file may be "
                          "truncated, or was not closed by its writer)",
                          offset, fileSize - std::min(fileSize, firstChunk), firstChunk));
  return uint64_t(offset);
}

}  // namespace

uint32_t checkLaszipRecord(const InputStream& in, const LasHeader& header,
                           std::span<const std::byte> payload) {
  const auto fail = [&](const std::string& reason) { in.failAt(0, reason); };
  if (payload.empty()) fail("no LASzip VLR (user \"laszip encoded\", record 22204): not LAZ");
  if (payload.size() < kItemsAt)
    fail(fmt::format("the LASzip VLR holds {} bytes, fewer than its {} fixed ones", payload.size(),
                     kItemsAt));
  const auto u16 = [&](size_t at) { return loadLittleEndian<uint16_t>(payload.data() + at); };
  const uint16_t compressor = u16(kCompressorAt);
  const uint16_t itemCount = u16(kItemCountAt);
  if (payload.size() < kItemsAt + kItemBytes * itemCount)
    fail(fmt::format("the LASzip VLR announces {} items but holds {}", itemCount,
                     (payload.size() - kItemsAt) / kItemBytes));
  if (u16(kCoderAt) != 0) fail(fmt::format("unknown LASzip coder {}", u16(kCoderAt)));
  const int format = header.pointFormat;
  if (format == 4 || format == 5 || format >= 9)
    fail(
        fmt::format("LAZ point format {} (with waveform packets) is not decoded: laz-perf "
                    "decodes point formats 0-3 and 6-8",
                    format));
  if (compressor == kNone || compressor == kPointwise)
    fail(
        fmt::format("LASzip compressor {} ({}) is not decoded: laz-perf decodes chunked LAZ "
                    "(LASzip 2 and later)",
                    compressor, compressor == kNone ? "none" : "pointwise, without chunks"));
  const uint16_t expected = format <= 3 ? kPointwiseChunked : kLayeredChunked;
  if (compressor != expected)
    fail(fmt::format("LASzip compressor {} does not fit point format {} (it takes {})", compressor,
                     format, expected));
  if (header.recordLength > 0xFFFF) fail("point record length over 65535 bytes");
  const auto extraBytes = uint16_t(header.recordLength - kStandardRecord[format]);
  const std::vector<Item> items = expectedItems(format, extraBytes);
  for (size_t i = 0; i < std::max<size_t>(items.size(), itemCount); ++i) {
    if (i >= itemCount || i >= items.size())
      fail(
          fmt::format("the LASzip VLR lists {} items where point format {} with {} extra bytes "
                      "has {}",
                      itemCount, format, extraBytes, items.size()));
    const Item found{u16(kItemsAt + kItemBytes * i), u16(kItemsAt + kItemBytes * i + 2),
                     u16(kItemsAt + kItemBytes * i + 4)};
    const Item& want = items[i];
    if (found.type != want.type || found.size != want.size)
      fail(
          fmt::format("LASzip item {} is {} of {} bytes where point format {} (record of {} "
                      "bytes) has {} of {}",
                      i + 1, itemName(found.type), found.size, format, header.recordLength,
                      itemName(want.type), want.size));
    if (found.version != want.version)
      fail(fmt::format(
          "LASzip item {} version {} is not decoded: laz-perf decodes version {} "
          "(written by LASzip {} and later)",
          itemName(found.type), found.version, want.version, want.version == 2 ? "2" : "3"));
  }
  const uint32_t chunkSize = loadLittleEndian<uint32_t>(payload.data() + kChunkSizeAt);
  if (chunkSize == 0) fail("the LASzip VLR's chunk size is 0");
  return chunkSize;
}

std::vector<LazChunk> readLazChunkTable(InputStream& in, const LasHeader& header,
                                        uint32_t chunkSize, uint64_t fileSize) {
  const uint64_t firstChunk = header.pointDataOffset + 8;
  const uint64_t tableAt = chunkTableOffset(in, header, fileSize);
  const auto fail = [&](const std::string& reason) {
    in.failAt(tableAt, "damaged chunk table: " + reason);
  };
  std::array<std::byte, 8> head{};
  in.seek(tableAt);
  if (!in.readExact(head.data(), 8)) fail("the file ends inside it");
  const uint32_t version = loadLittleEndian<uint32_t>(head.data());
  const uint64_t count = loadLittleEndian<uint32_t>(head.data() + 4);
  if (version != 0) fail(fmt::format("unknown version {} (LASzip writes 0)", version));
  // Every chunk holding points takes at least its first point's bytes.
  if (count > (tableAt - firstChunk) / header.recordLength + 1)
    fail(fmt::format("{} chunks in {} bytes of point data", count, tableAt - firstChunk));
  if (count > kMaxChunks)
    fail(fmt::format("{} chunks, more than the {} this reader takes", count, kMaxChunks));
  const bool isVariable = chunkSize == kLazVariableChunkSize;
  // Chunks of a fixed size hold no count: the header's count says how many there are (the last
  // may be partial; a file of no points may have one, empty).
  const uint64_t needed = isVariable ? count : (header.pointCount + chunkSize - 1) / chunkSize;
  if (count != needed && !(header.pointCount == 0 && count <= 1))
    fail(fmt::format("it lists {} chunks, but {} points in chunks of {} take {}", count,
                     header.pointCount, chunkSize, needed));
  // The table ends where the file ends (or EVLRs begin); the decoder reads ahead a few bytes.
  TableBytes source(in, fileSize - tableAt - 8);
  laz::ArithmeticDecoder decoder(source);
  laz::IntegerModels models(32, 2);  // the count in context 0, the size in context 1
  std::vector<LazChunk> chunks(static_cast<size_t>(count));
  uint32_t points = 0, size = 0;
  uint64_t offset = firstChunk, remaining = header.pointCount;
  for (size_t i = 0; i < chunks.size(); ++i) {
    if (isVariable) points = decoder.decodeInteger(models, points, 0);
    size = decoder.decodeInteger(models, size, 1);
    if (source.isOverrun()) fail(fmt::format("the file ends inside entry {} of {}", i + 1, count));
    LazChunk& chunk = chunks[i];
    chunk.offset = offset;
    chunk.bytes = size;
    chunk.points = isVariable ? points : std::min<uint64_t>(chunkSize, remaining);
    if (chunk.points > remaining)
      fail(fmt::format("its chunks hold more points than the header's {}", header.pointCount));
    remaining -= chunk.points;
    if (chunk.bytes > tableAt - offset)
      fail(fmt::format("chunk {} of {} bytes at byte {} runs past the chunk table at byte {}",
                       i + 1, chunk.bytes, offset, tableAt));
    if (chunk.bytes > kMaxLazChunkBytes)
      fail(fmt::format("chunk {} takes {} bytes, more than the {} a chunk may take here", i + 1,
                       chunk.bytes, kMaxLazChunkBytes));
    if (chunk.points > 0 && chunk.bytes < header.recordLength)
      fail(fmt::format("chunk {} holds {} points in {} bytes, fewer than its first point's {}",
                       i + 1, chunk.points, chunk.bytes, header.recordLength));
    offset += chunk.bytes;
  }
  if (remaining > 0)
    fail(fmt::format("its chunks hold {} points, the header says {}", header.pointCount - remaining,
                     header.pointCount));
  return chunks;
}

}  // namespace iso::io
