// The LAZ reader: a LAS header and VLRs (las_format.h, las_records.h), the LASzip container
// (laz_chunks.h), and chunks decoded ahead by laz-perf on every core (laz_stream.h) into the
// same records a LAS file of the same points holds, which the LAS record decoder turns into
// points. So a LAZ file gives exactly the points of the LAS file it decompresses to.
#include <fmt/format.h>

#include <algorithm>
#include <optional>

#include "iso/error.h"
#include "pipeline/io/las_format.h"
#include "pipeline/io/las_records.h"
#include "pipeline/io/laz_chunks.h"
#include "pipeline/io/laz_decoder.h"
#include "pipeline/io/laz_stream.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {
namespace {

class LazPointReader final : public PointReader {
 public:
  LazPointReader(InputStream in, const LasHeader& header, const ReadOptions& options)
      : header_(header), keepExtras_(options.keepExtras) {
    info_.path = in.path();
    info_.format = lasFormatName(header_);
    info_.declaredPoints = header_.pointCount;
    info_.hasColors = lasRgbOffset(header_.pointFormat) != 0;
    if (keepExtras_) info_.extraNames = lasExtraNames(header_.pointFormat);
    if (!hasLazDecoder()) in.failAt(0, kLazDecoderMissing);
    if (!in.knownSize())
      in.failAt(0, "a compressed copy of a LAZ file is not read: decompress it (gunzip) first");
    std::vector<std::byte> laszip;
    info_.crs =
        readLasCoordinateSystem(in, header_, header_.pointDataOffset + 8, info_.notes, &laszip);
    const uint32_t chunkSize = checkLaszipRecord(in, header_, laszip);
    std::vector<LazChunk> chunks = readLazChunkTable(in, header_, chunkSize, *in.knownSize());
    stream_.emplace(std::make_shared<SharedFile>(in.path()), header_.pointFormat,
                    size_t(header_.recordLength), std::move(chunks));
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    if (!decoder_) probeColors();
    size_t appended = 0;
    while (appended < maxPoints) {
      std::span<const std::byte> records;
      if (probed_ < probedRecords_.size()) {
        const size_t count = std::min((probedRecords_.size() - probed_) / header_.recordLength,
                                      maxPoints - appended);
        records = std::span(probedRecords_).subspan(probed_, count * header_.recordLength);
        probed_ += records.size();
      } else {
        records = stream_->next(maxPoints - appended);
        if (records.empty()) break;
      }
      const size_t count = records.size() / header_.recordLength;
      appended += decoder_->append(records.data(), count, out, stats_);
    }
    stats_.pointsRead += appended;
    return appended;
  }

 private:
  // Decide how the colors are coded from the first records, as the LAS reader does, keeping
  // them to be read.
  void probeColors() {
    LasColorCoding coding = LasColorCoding::kSixteen;
    if (info_.hasColors) {
      const uint64_t wanted = lasColorProbeRecords(header_);
      while (probedRecords_.size() < wanted * header_.recordLength) {
        const std::span<const std::byte> records =
            stream_->next(size_t(wanted - probedRecords_.size() / header_.recordLength));
        if (records.empty()) break;
        probedRecords_.insert(probedRecords_.end(), records.begin(), records.end());
      }
      coding = probeLasColorCoding(header_, probedRecords_.data(),
                                   probedRecords_.size() / header_.recordLength);
      if (coding == LasColorCoding::kEightTimes256) info_.notes.push_back(kLasColorsTimes256Note);
    }
    decoder_.emplace(header_, coding, keepExtras_);
  }

  LasHeader header_;
  bool keepExtras_;
  std::optional<LazChunkStream> stream_;
  std::optional<LasRecordDecoder> decoder_;
  std::vector<std::byte> probedRecords_;  // the records the colors were probed on
  size_t probed_ = 0;                     // bytes of them read
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::unique_ptr<PointReader> makeLazReader(InputStream in, const LasHeader& header,
                                           const ReadOptions& options) {
  return std::make_unique<LazPointReader>(std::move(in), header, options);
}

}  // namespace iso::io
