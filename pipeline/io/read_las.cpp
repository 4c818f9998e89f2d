// The LAS reader, versions 1.0–1.4, point data formats 0–10 (ASPRS LAS Specification 1.4 R15,
// section 2.4 "Public Header Block" and 2.6–2.16 "Point Data Records"; all fields little endian),
// with the coordinate system of its VLRs and EVLRs (las_records.h).
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "iso/error.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/las_records.h"
#include "pipeline/io/little_endian.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {
namespace {

// Public header fields (byte offsets, LAS 1.4 Table 3; the same in earlier versions).
constexpr size_t kVersionMajorAt = 24;
constexpr size_t kVersionMinorAt = 25;
constexpr size_t kHeaderSizeAt = 94;
constexpr size_t kPointDataOffsetAt = 96;
constexpr size_t kVlrCountAt = 100;
constexpr size_t kPointFormatAt = 104;
constexpr size_t kRecordLengthAt = 105;
constexpr size_t kLegacyPointCountAt = 107;
constexpr size_t kScaleAt = 131;       // x y z doubles
constexpr size_t kOffsetAt = 155;      // x y z doubles
constexpr size_t kEvlrStartAt = 235;   // LAS 1.4: offset of the first EVLR
constexpr size_t kEvlrCountAt = 243;   // LAS 1.4: number of EVLRs
constexpr size_t kPointCountAt = 247;  // LAS 1.4: 64-bit number of point records

// Public header of LAS 1.0–1.3 (1.3 appends the waveform start, which is not read, so its absence
// is tolerated) and of LAS 1.4 (appends EVLRs and the 64-bit counts, which are needed).
constexpr size_t kHeaderSize12 = 227;
constexpr size_t kHeaderSize14 = 375;

// The LAZ compressor marks compressed point formats by setting bit 7 (bit 6 in early versions).
constexpr uint8_t kCompressedFormatBits = 0xC0;

constexpr int kMaxFormat = 10;
// Standard record size of each point data format, and where its RGB channels start (0: none).
constexpr uint16_t kRecordSize[kMaxFormat + 1] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
constexpr uint16_t kRgbAt[kMaxFormat + 1] = {0, 0, 20, 28, 0, 28, 0, 30, 30, 0, 30};

// Points and bytes examined to tell 8-bit from 16-bit colors.
constexpr uint64_t kColorProbePoints = 65536;
constexpr size_t kColorProbeBytes = size_t{16} << 20;

template <typename T>
T load(const std::byte* p) {
  return loadLittleEndian<T>(p);
}

glm::dvec3 loadVector(const std::byte* p) {
  return {load<double>(p), load<double>(p + 8), load<double>(p + 16)};
}

// How the 16-bit RGB fields of a file hold its colors.
enum class ColorCoding : uint8_t { kEight, kEightTimes256, kSixteen };

struct LasHeader {
  int versionMajor = 1;
  int versionMinor = 2;
  uint64_t headerSize = 0;
  uint64_t pointDataOffset = 0;
  uint32_t vlrCount = 0;
  uint64_t evlrStart = 0;  // LAS 1.4
  uint32_t evlrCount = 0;  // LAS 1.4
  int pointFormat = 0;
  uint64_t recordLength = 0;
  uint64_t pointCount = 0;
  glm::dvec3 scale{1.0};
  glm::dvec3 offset{0.0};
};

// Check what the fixed fields promise before anything depends on them.
void validate(const InputStream& in, const LasHeader& h, int rawFormat) {
  const auto fail = [&](const std::string& reason) { in.failAt(0, reason); };
  if ((rawFormat & kCompressedFormatBits) != 0) fail(kLazNotSupported);
  if (h.versionMajor != 1 || h.versionMinor > 4)
    fail(fmt::format("unsupported LAS version {}.{} (supported: 1.0 to 1.4)", h.versionMajor,
                     h.versionMinor));
  if (h.pointFormat > kMaxFormat)
    fail(fmt::format("unsupported LAS point data format {} (supported: 0 to 10)", h.pointFormat));
  const size_t minimum = h.versionMinor >= 4 ? kHeaderSize14 : kHeaderSize12;
  if (h.headerSize < minimum)
    fail(fmt::format("header size {} is smaller than the LAS {}.{} header ({} bytes)", h.headerSize,
                     h.versionMajor, h.versionMinor, minimum));
  if (h.pointDataOffset < h.headerSize)
    fail(fmt::format("offset to point data {} lies inside the {}-byte header", h.pointDataOffset,
                     h.headerSize));
  if (h.recordLength < kRecordSize[h.pointFormat])
    fail(fmt::format("point record length {} is smaller than the {} bytes of point format {}",
                     h.recordLength, kRecordSize[h.pointFormat], h.pointFormat));
  for (int axis = 0; axis < 3; ++axis)
    if (!std::isfinite(h.scale[axis]) || h.scale[axis] == 0.0 || !std::isfinite(h.offset[axis]))
      fail("scale factors must be finite and non-zero, offsets finite");
}

LasHeader readHeader(InputStream& in, bool isLazByName) {
  std::span<const std::byte> bytes = in.peek(kHeaderSize12);
  if (bytes.size() < 4 || std::memcmp(bytes.data(), "LASF", 4) != 0)
    in.failAt(0, "not a LAS file: no LASF signature");
  if (isLazByName) in.failAt(0, kLazNotSupported);
  if (bytes.size() < kHeaderSize12)
    in.failAt(bytes.size(), fmt::format("file ends inside the LAS header ({} of {} bytes)",
                                        bytes.size(), kHeaderSize12));
  const std::byte* p = bytes.data();
  LasHeader h;
  h.versionMajor = static_cast<int>(p[kVersionMajorAt]);
  h.versionMinor = static_cast<int>(p[kVersionMinorAt]);
  h.headerSize = load<uint16_t>(p + kHeaderSizeAt);
  h.pointDataOffset = load<uint32_t>(p + kPointDataOffsetAt);
  h.vlrCount = load<uint32_t>(p + kVlrCountAt);
  const int rawFormat = static_cast<int>(p[kPointFormatAt]);
  h.pointFormat = rawFormat & ~kCompressedFormatBits;
  h.recordLength = load<uint16_t>(p + kRecordLengthAt);
  h.pointCount = load<uint32_t>(p + kLegacyPointCountAt);
  h.scale = loadVector(p + kScaleAt);
  h.offset = loadVector(p + kOffsetAt);
  validate(in, h, rawFormat);
  if (h.versionMinor >= 4) {
    bytes = in.peek(kHeaderSize14);
    if (bytes.size() < kHeaderSize14)
      in.failAt(bytes.size(), fmt::format("file ends inside the LAS 1.4 header ({} of {} bytes)",
                                          bytes.size(), kHeaderSize14));
    // LAS 1.4 keeps the legacy count zero when the 64-bit count does not fit it, or for formats
    // 6–10; the 64-bit count is authoritative when set.
    const uint64_t count = load<uint64_t>(bytes.data() + kPointCountAt);
    if (count != 0) h.pointCount = count;
    h.evlrStart = load<uint64_t>(bytes.data() + kEvlrStartAt);
    h.evlrCount = load<uint32_t>(bytes.data() + kEvlrCountAt);
  }
  return h;
}

// Reject point data that cannot be all there, before reading it, when the file size is known.
void checkAgainstFileSize(const InputStream& in, const LasHeader& h) {
  if (!in.knownSize()) return;
  const uint64_t size = *in.knownSize();
  if (h.pointDataOffset > size)
    in.failAt(size, fmt::format("the point data offset {} is past the end of the file ({} bytes)",
                                h.pointDataOffset, size));
  const uint64_t available = (size - h.pointDataOffset) / h.recordLength;
  if (available < h.pointCount)
    in.failAt(h.pointDataOffset + available * h.recordLength,
              fmt::format("file ends after {} of {} points", available, h.pointCount));
}

class LasPointReader final : public PointReader {
 public:
  LasPointReader(InputStream in, bool isLazByName)
      : in_(std::move(in)), header_(readHeader(in_, isLazByName)) {
    checkAgainstFileSize(in_, header_);
    info_.path = in_.path();
    readCoordinateSystem();
    const uint64_t toPointData = header_.pointDataOffset - in_.offset();
    if (in_.skip(toPointData) != toPointData)
      in_.fail(fmt::format("file ends before the point data at byte {}", header_.pointDataOffset));
    rgbAt_ = kRgbAt[header_.pointFormat];
    info_.format = fmt::format("las {}.{} format {}", header_.versionMajor, header_.versionMinor,
                               header_.pointFormat);
    info_.declaredPoints = header_.pointCount;
    info_.hasColors = rgbAt_ != 0;
    if (info_.hasColors) colorCoding_ = probeColorCoding();
    if (colorCoding_ == ColorCoding::kEightTimes256)
      info_.notes.push_back(
          "its colors are 8-bit codes times 256 (every low byte 0): read as 8-bit codes");
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    size_t appended = 0;
    while (appended < maxPoints && pointsDone_ < header_.pointCount) {
      const std::span<const std::byte> bytes = in_.peek(header_.recordLength);
      if (bytes.size() < header_.recordLength)
        in_.fail(fmt::format("file ends after {} of {} points", pointsDone_, header_.pointCount));
      const size_t count = static_cast<size_t>(
          std::min<uint64_t>({bytes.size() / header_.recordLength, maxPoints - appended,
                              header_.pointCount - pointsDone_}));
      appended += appendRecords(bytes.data(), count, out);
      in_.consume(count * header_.recordLength);
      pointsDone_ += count;
    }
    stats_.pointsRead += appended;
    return appended;
  }

 private:
  // The coordinate system from the VLRs (between the header and the point data), else from the
  // EVLRs of LAS 1.4 (after the point data). Leaves the stream at the end of the VLRs.
  void readCoordinateSystem() {
    if (in_.skip(header_.headerSize) != header_.headerSize)
      in_.fail(fmt::format("file ends inside the {}-byte header", header_.headerSize));
    LasCoordinateRecords records;
    readLasVlrs(in_, header_.pointDataOffset, header_.vlrCount, records, info_.notes);
    if (!records.hasWkt() && header_.evlrCount > 0) {
      const uint64_t maxPoints =
          (std::numeric_limits<uint64_t>::max() - header_.pointDataOffset) / header_.recordLength;
      const uint64_t pointDataEnd =
          header_.pointCount > maxPoints
              ? std::numeric_limits<uint64_t>::max()
              : header_.pointDataOffset + header_.pointCount * header_.recordLength;
      readLasEvlrs(in_.path(), header_.evlrStart, header_.evlrCount, pointDataEnd, records,
                   info_.notes);
    }
    info_.crs = records.coordinateSystem(info_.notes);
  }

  // Many writers store 8-bit colors in the 16-bit RGB fields, as they are (0–255) or times 256
  // (0–65280, every low byte 0). Decide per file from the channels of the first (up to) 64k
  // points: none above 255 is 8-bit; every low byte 0 is 8-bit times 256; otherwise 16-bit.
  ColorCoding probeColorCoding() {
    const uint64_t wanted =
        std::min<uint64_t>({header_.pointCount, kColorProbePoints,
                            std::max<uint64_t>(1, kColorProbeBytes / header_.recordLength)});
    const std::span<const std::byte> bytes = in_.peek(wanted * header_.recordLength);
    const size_t count = std::min<size_t>(wanted, bytes.size() / header_.recordLength);
    uint16_t largest = 0;
    uint16_t lowBits = 0;
    for (size_t i = 0; i < count; ++i) {
      const std::byte* rgb = bytes.data() + i * header_.recordLength + rgbAt_;
      for (int channel = 0; channel < 3; ++channel) {
        const uint16_t value = load<uint16_t>(rgb + 2 * channel);
        largest = std::max(largest, value);
        lowBits |= value & 0xFFu;
      }
    }
    if (largest <= 255) return ColorCoding::kEight;
    return lowBits == 0 ? ColorCoding::kEightTimes256 : ColorCoding::kSixteen;
  }

  // Decode `count` records into out, dropping non-finite positions; returns the points appended.
  size_t appendRecords(const std::byte* records, size_t count, PointCloud& out) {
    const std::array<float, 65536>& table = srgb16ToLinearTable();
    const auto channel = [&](const std::byte* p) {
      const uint16_t value = load<uint16_t>(p);
      switch (colorCoding_) {
        case ColorCoding::kEight:  // later values above 255 are clamped
          return table[size_t{std::min<uint16_t>(value, 255)} * 257];
        case ColorCoding::kEightTimes256:  // later values with low bits are rounded
          return table[std::min<size_t>((size_t{value} + 128) >> 8, 255) * 257];
        case ColorCoding::kSixteen:
          break;
      }
      return table[value];
    };
    const size_t first = out.positions.size();
    size_t written = first;
    out.positions.resize(first + count);
    if (rgbAt_ != 0) out.colors.resize(first + count);
    for (size_t i = 0; i < count; ++i) {
      const std::byte* record = records + i * header_.recordLength;
      const glm::dvec3 integer{load<int32_t>(record), load<int32_t>(record + 4),
                               load<int32_t>(record + 8)};
      const glm::dvec3 position = integer * header_.scale + header_.offset;
      if (!isFinite(position)) {
        ++stats_.droppedNonFinite;
        continue;
      }
      out.positions[written] = position;
      if (rgbAt_ != 0) {
        const std::byte* rgb = record + rgbAt_;
        out.colors[written] = {channel(rgb), channel(rgb + 2), channel(rgb + 4)};
      }
      ++written;
    }
    out.positions.resize(written);
    if (rgbAt_ != 0) out.colors.resize(written);
    return written - first;
  }

  InputStream in_;
  LasHeader header_;
  size_t rgbAt_ = 0;
  ColorCoding colorCoding_ = ColorCoding::kSixteen;
  uint64_t pointsDone_ = 0;
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::unique_ptr<PointReader> makeLasReader(InputStream in) {
  const bool isLazByName = lowercaseExtension(in.path()) == ".laz";
  return std::make_unique<LasPointReader>(std::move(in), isLazByName);
}

}  // namespace iso::io
