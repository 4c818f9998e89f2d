// The LAS reader, versions 1.0–1.4, point data formats 0–10 (las_format.h), with the coordinate
// system of its VLRs and EVLRs (las_records.h). Compressed files go to the LAZ reader.
#include <fmt/format.h>

#include <algorithm>
#include <limits>

#include "iso/error.h"
#include "pipeline/io/las_format.h"
#include "pipeline/io/las_records.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {
namespace {

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
  LasPointReader(InputStream in, const LasHeader& header, const ReadOptions& options,
                 bool isLazByName)
      : in_(std::move(in)), header_(header) {
    checkAgainstFileSize(in_, header_);
    info_.path = in_.path();
    const uint64_t maxPoints =
        (std::numeric_limits<uint64_t>::max() - header_.pointDataOffset) / header_.recordLength;
    const uint64_t pointDataEnd =
        header_.pointCount > maxPoints
            ? std::numeric_limits<uint64_t>::max()
            : header_.pointDataOffset + header_.pointCount * header_.recordLength;
    info_.crs = readLasCoordinateSystem(in_, header_, pointDataEnd, info_.notes);
    const uint64_t toPointData = header_.pointDataOffset - in_.offset();
    if (in_.skip(toPointData) != toPointData)
      in_.fail(fmt::format("file ends before the point data at byte {}", header_.pointDataOffset));
    info_.format = lasFormatName(header_);
    info_.declaredPoints = header_.pointCount;
    info_.hasColors = lasRgbOffset(header_.pointFormat) != 0;
    LasColorCoding coding = LasColorCoding::kSixteen;
    if (info_.hasColors) coding = probeColorCoding();
    if (coding == LasColorCoding::kEightTimes256) info_.notes.push_back(kLasColorsTimes256Note);
    decoder_.emplace(header_, coding, options.keepExtras);
    info_.extraNames = decoder_->extraNames();
    if (isLazByName)
      info_.notes.push_back("named .laz but its points are not compressed: read as LAS");
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
      appended += decoder_->append(bytes.data(), count, out, stats_);
      in_.consume(count * header_.recordLength);
      pointsDone_ += count;
    }
    stats_.pointsRead += appended;
    return appended;
  }

 private:
  LasColorCoding probeColorCoding() {
    const uint64_t wanted = lasColorProbeRecords(header_);
    const std::span<const std::byte> bytes = in_.peek(wanted * header_.recordLength);
    const size_t count = std::min<size_t>(wanted, bytes.size() / header_.recordLength);
    return probeLasColorCoding(header_, bytes.data(), count);
  }

  InputStream in_;
  LasHeader header_;
  std::optional<LasRecordDecoder> decoder_;
  uint64_t pointsDone_ = 0;
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::unique_ptr<PointReader> makeLasReader(InputStream in, const ReadOptions& options) {
  const LasHeader header = readLasHeader(in);
  if (header.isCompressed) return makeLazReader(std::move(in), header, options);
  const bool isLazByName = lowercaseExtension(in.path()) == ".laz";
  return std::make_unique<LasPointReader>(std::move(in), header, options, isLazByName);
}

}  // namespace iso::io
