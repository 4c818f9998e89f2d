// The PLY point reader: the vertex element of ASCII and binary PLY files.
#include <fmt/format.h>

#include "iso/error.h"
#include "pipeline/io/ply_format.h"
#include "pipeline/io/ply_vertices.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {
namespace {

// Skip the elements before the vertex element; the stream is then at its first record.
PlyVertexDecoder seekVertices(InputStream& in, const PlyHeader& header, bool keepExtras) {
  const std::optional<size_t> vertex = header.find("vertex");
  if (!vertex) throw FileError(in.name(), std::nullopt, "the PLY file has no vertex element");
  for (size_t i = 0; i < *vertex; ++i) skipPlyElement(in, header.encoding, header.elements[i]);
  return PlyVertexDecoder(in, header.encoding, header.elements[*vertex], false, keepExtras);
}

class PlyPointReader final : public PointReader {
 public:
  PlyPointReader(InputStream in, const ReadOptions& options)
      : in_(std::move(in)),
        header_(readPlyHeader(in_)),
        decoder_(seekVertices(in_, header_, options.keepExtras)) {
    info_.path = in_.path();
    info_.format = plyFormatName(header_.encoding);
    info_.declaredPoints = decoder_.remainingRecords();
    info_.hasNormals = decoder_.hasNormals();
    info_.hasColors = decoder_.hasColors();
    info_.extraNames = decoder_.extraNames();
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    size_t appended = 0;
    while (appended < maxPoints && decoder_.remainingRecords() > 0) {
      const size_t before = out.size();
      decoder_.decode(in_, out, maxPoints - appended);
      appended += out.size() - before;
    }
    stats_.pointsRead += appended;
    stats_.droppedNonFinite = decoder_.droppedNonFinite();
    return appended;
  }

 private:
  InputStream in_;
  PlyHeader header_;
  PlyVertexDecoder decoder_;
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::unique_ptr<PointReader> makePlyReader(InputStream in, const ReadOptions& options) {
  return std::make_unique<PlyPointReader>(std::move(in), options);
}

}  // namespace iso::io
