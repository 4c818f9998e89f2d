#include "pipeline/io/las_format.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "pipeline/io/color_table.h"
#include "pipeline/io/little_endian.h"
#include "pipeline/io/non_finite.h"

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

// LASzip marks compressed point formats by setting bit 7 (bit 6 in early versions).
constexpr uint8_t kCompressedFormatBits = 0xC0;

constexpr int kMaxFormat = 10;
// Standard record size of each point data format, and where its RGB channels start (0: none).
constexpr uint16_t kRecordSize[kMaxFormat + 1] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
constexpr uint16_t kRgbAt[kMaxFormat + 1] = {0, 0, 20, 28, 0, 28, 0, 30, 30, 0, 30};
constexpr size_t kIntensityAt = 12;  // u16 in every format

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

// Check what the fixed fields promise before anything depends on them.
void validate(const InputStream& in, const LasHeader& h) {
  const auto fail = [&](const std::string& reason) { in.failAt(0, reason); };
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

}  // namespace

LasHeader readLasHeader(InputStream& in) {
  std::span<const std::byte> bytes = in.peek(kHeaderSize12);
  if (bytes.size() < 4 || std::memcmp(bytes.data(), "LASF", 4) != 0)
    in.failAt(0, "not a LAS file: no LASF signature");
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
  const auto rawFormat = static_cast<uint8_t>(p[kPointFormatAt]);
  h.pointFormat = rawFormat & ~kCompressedFormatBits;
  h.isCompressed = (rawFormat & kCompressedFormatBits) != 0;
  h.recordLength = load<uint16_t>(p + kRecordLengthAt);
  h.pointCount = load<uint32_t>(p + kLegacyPointCountAt);
  h.scale = loadVector(p + kScaleAt);
  h.offset = loadVector(p + kOffsetAt);
  validate(in, h);
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

std::string lasFormatName(const LasHeader& header) {
  return fmt::format("{} {}.{} format {}", header.isCompressed ? "laz" : "las", header.versionMajor,
                     header.versionMinor, header.pointFormat);
}

size_t lasRgbOffset(int pointFormat) { return kRgbAt[pointFormat]; }

uint64_t lasColorProbeRecords(const LasHeader& header) {
  return std::min<uint64_t>({header.pointCount, kColorProbePoints,
                             std::max<uint64_t>(1, kColorProbeBytes / header.recordLength)});
}

LasColorCoding probeLasColorCoding(const LasHeader& header, const std::byte* records,
                                   size_t count) {
  const size_t rgbAt = kRgbAt[header.pointFormat];
  uint16_t largest = 0;
  uint16_t lowBits = 0;
  for (size_t i = 0; i < count; ++i) {
    const std::byte* rgb = records + i * header.recordLength + rgbAt;
    for (int channel = 0; channel < 3; ++channel) {
      const uint16_t value = load<uint16_t>(rgb + 2 * channel);
      largest = std::max(largest, value);
      lowBits |= value & 0xFFu;
    }
  }
  if (largest <= 255) return LasColorCoding::kEight;
  return lowBits == 0 ? LasColorCoding::kEightTimes256 : LasColorCoding::kSixteen;
}

std::vector<std::string> lasExtraNames(int pointFormat) {
  std::vector<std::string> names = {"intensity", "return_number", "classification"};
  if (pointFormat != 0 && pointFormat != 2) names.push_back("gps_time");
  return names;
}

LasRecordDecoder::LasRecordDecoder(const LasHeader& header, LasColorCoding coding, bool keepExtras)
    : scale_(header.scale),
      offset_(header.offset),
      recordLength_(header.recordLength),
      rgbAt_(kRgbAt[header.pointFormat]),
      coding_(coding),
      extended_(header.pointFormat >= 6) {
  if (keepExtras) extraNames_ = lasExtraNames(header.pointFormat);
}

size_t LasRecordDecoder::append(const std::byte* records, size_t count, PointCloud& out,
                                ReadStats& stats) const {
  const std::array<float, 65536>& table = srgb16ToLinearTable();
  const auto channel = [&](const std::byte* p) {
    const uint16_t value = load<uint16_t>(p);
    switch (coding_) {
      case LasColorCoding::kEight:  // later values above 255 are clamped
        return table[size_t{std::min<uint16_t>(value, 255)} * 257];
      case LasColorCoding::kEightTimes256:  // later values with low bits are rounded
        return table[std::min<size_t>((size_t{value} + 128) >> 8, 255) * 257];
      case LasColorCoding::kSixteen:
        break;
    }
    return table[value];
  };
  const size_t extras = extraNames_.size();
  if (extras > 0) out.extraNames = extraNames_;
  const size_t first = out.positions.size();
  size_t written = first;
  out.positions.resize(first + count);
  if (rgbAt_ != 0) out.colors.resize(first + count);
  out.extras.resize((first + count) * extras);
  for (size_t i = 0; i < count; ++i) {
    const std::byte* record = records + i * recordLength_;
    const glm::dvec3 integer{load<int32_t>(record), load<int32_t>(record + 4),
                             load<int32_t>(record + 8)};
    const glm::dvec3 position = integer * scale_ + offset_;
    if (!isFinite(position)) {
      ++stats.droppedNonFinite;
      continue;
    }
    out.positions[written] = position;
    if (rgbAt_ != 0) {
      const std::byte* rgb = record + rgbAt_;
      out.colors[written] = {channel(rgb), channel(rgb + 2), channel(rgb + 4)};
    }
    if (extras > 0) {
      // Formats 0-5: return number in bits 0-2 of byte 14, classification in bits 0-4 of byte 15,
      // GPS time at 20; formats 6-10: bits 0-3 of byte 14, byte 16, at 22 (LAS 1.4 R15, 2.6-2.16).
      double* e = out.extras.data() + written * extras;
      const uint8_t returns = load<uint8_t>(record + 14);
      e[0] = double(load<uint16_t>(record + kIntensityAt));
      e[1] = double(extended_ ? returns & 15 : returns & 7);
      e[2] = double(extended_ ? load<uint8_t>(record + 16) : load<uint8_t>(record + 15) & 31);
      if (extras > 3) e[3] = load<double>(record + (extended_ ? 22 : 20));
    }
    ++written;
  }
  out.positions.resize(written);
  if (rgbAt_ != 0) out.colors.resize(written);
  out.extras.resize(written * extras);
  return written - first;
}

}  // namespace iso::io
