// Decoding of a PLY vertex element into point batches, for the PLY point and mesh readers.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/ply_format.h"
#include "pipeline/io/point_cloud.h"

namespace iso::io {

// Reads the records of the vertex element: x y z (required, any scalar type), nx ny nz (when all
// three are present) and colors red green blue, r g b or diffuse_red diffuse_green diffuse_blue
// (when all three are present; 8-bit types as 0–255, 16-bit as 0–65535, 32-bit integers as 0–255,
// floats as 0–1; sRGB decoded to linear). Other scalar properties are skipped, or carried as float
// extras in header order when asked for; lists are always skipped.
class PlyVertexDecoder {
 public:
  // The stream must be at the element's first record. Points with a non-finite coordinate are
  // dropped and counted unless keepNonFinite (a mesh needs every vertex for its indices). With
  // keepExtras, the other scalar properties are decoded as extras. Throws iso::FileError when x, y
  // or z is missing or a list.
  PlyVertexDecoder(const InputStream& in, PlyEncoding encoding, const PlyElement& vertex,
                   bool keepNonFinite, bool keepExtras = false);

  bool hasNormals() const { return hasNormals_; }
  bool hasColors() const { return hasColors_; }
  // Names of the extras, in header order (empty unless keepExtras).
  const std::vector<std::string>& extraNames() const { return extraNames_; }
  uint64_t remainingRecords() const { return remaining_; }
  uint64_t droppedNonFinite() const { return dropped_; }

  // Decode up to maxRecords more records, appending their points to out (normals and colors when
  // the element has them, and extras, setting out.extraNames; out must not hold points with other
  // extras). Returns the number of records read. Throws iso::FileError when the file ends early or
  // a value is malformed.
  size_t decode(InputStream& in, PointCloud& out, size_t maxRecords);

 private:
  enum Slot : uint8_t { kX, kY, kZ, kNx, kNy, kNz, kRed, kGreen, kBlue, kSlotCount };
  struct SlotSource {
    PlyType type = PlyType::Float32;
    size_t offset = 0;     // in a binary record with its lists left out
    double fullScale = 1;  // colors: the value of full intensity
  };

  // The extras: every scalar property without a slot, in header order.
  void findExtras(const PlyElement& vertex, const std::vector<size_t>& offsets);
  void adoptExtraNames(PointCloud& out) const;
  size_t decodeBinary(InputStream& in, PointCloud& out, size_t maxRecords);
  size_t decodeBinaryWithLists(InputStream& in, PointCloud& out, size_t maxRecords);
  size_t decodeAscii(InputStream& in, PointCloud& out, size_t maxRecords);
  // Append the points of `count` packed binary records.
  void appendRecords(const std::byte* records, size_t count, PointCloud& out);
  template <bool kBigEndian>
  void appendRecordsAs(const std::byte* records, size_t count, PointCloud& out);
  // Append one point from slot values followed by extra values (ASCII).
  void appendValues(const std::vector<double>& values, PointCloud& out);
  [[noreturn]] void failEndsEarly(const InputStream& in) const;

  PlyEncoding encoding_;
  PlyElement element_;
  std::array<SlotSource, kSlotCount> sources_{};
  std::vector<SlotSource> extraSources_;  // per extra
  std::vector<std::string> extraNames_;
  // Per property: its Slot, kSlotCount + its extra's index, or -1 when not decoded.
  std::vector<int32_t> targetOfProperty_;
  size_t recordBytes_ = 0;
  bool hasNormals_ = false;
  bool hasColors_ = false;
  bool keepNonFinite_ = false;
  uint64_t remaining_ = 0;
  uint64_t dropped_ = 0;
  std::vector<std::byte> scratch_;  // records gathered from around their lists
};

}  // namespace iso::io
