// The Draco reader: point clouds and meshes (whose vertices are the points) compressed with
// Google's Draco, decoded by libdraco. Draco decodes a whole buffer at once, so the reader decodes
// the file on opening and converts the decoded attributes batch by batch.
#include <draco/compression/decode.h>
#include <draco/compression/point_cloud/point_cloud_decoder.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/varint_decoding.h>
#include <draco/metadata/metadata_decoder.h>
#include <draco/point_cloud/point_cloud.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "iso/error.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {
namespace {

// Draco needs the whole file in memory; a gzip-compressed file could inflate without bound, so the
// reader refuses files beyond this size instead of exhausting memory.
constexpr uint64_t kMaxFileBytes = uint64_t{1} << 31;
constexpr size_t kChunkBytes = size_t{1} << 20;

// Draco trusts the point count of the geometry header and sizes every attribute by it before
// reading a value, so a corrupt count could exhaust memory. Scans compress to a few bytes per point
// and only degenerate clouds (repeated points) far below, so counts beyond this many points per
// byte of file are refused, once they exceed kAlwaysAllowedPoints.
constexpr uint64_t kMaxPointsPerByte = 64;
constexpr uint64_t kAlwaysAllowedPoints = uint64_t{1} << 22;

[[noreturn]] void failTooLarge(const InputStream& in) {
  in.failAt(kMaxFileBytes, fmt::format("the Draco file is larger than {} GiB, the most this reader "
                                       "decodes in memory",
                                       kMaxFileBytes >> 30));
}

std::vector<char> readWholeFile(InputStream& in) {
  std::vector<char> bytes;
  if (in.knownSize()) {
    if (*in.knownSize() > kMaxFileBytes) failTooLarge(in);
    bytes.reserve(static_cast<size_t>(*in.knownSize()));
  }
  for (;;) {
    const std::span<const std::byte> chunk = in.peek(kChunkBytes);
    if (chunk.empty()) return bytes;
    if (bytes.size() + chunk.size() > kMaxFileBytes) failTooLarge(in);
    const auto* data = reinterpret_cast<const char*>(chunk.data());
    bytes.insert(bytes.end(), data, data + chunk.size());
    in.consume(chunk.size());
  }
}

struct DeclaredPoints {
  int64_t count = 0;
  uint64_t offset = 0;  // of the count in the file
};

// The point count of the geometry header, read as Draco's decoders read it (Draco bitstream spec,
// "Header", "Metadata" and "Sequential Connectivity"): for point clouds, and for sequentially
// encoded meshes (edgebreaker meshes check their counts against the file size themselves).
// nullopt when there is none or it cannot be read; Draco then reports what is wrong.
std::optional<DeclaredPoints> declaredPoints(const std::vector<char>& bytes) {
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  draco::DracoHeader header;
  if (!draco::PointCloudDecoder::DecodeHeader(&buffer, &header).ok()) return std::nullopt;
  const uint16_t version = DRACO_BITSTREAM_VERSION(header.version_major, header.version_minor);
  buffer.set_bitstream_version(version);
  draco::GeometryMetadata metadata;
  if (version >= DRACO_BITSTREAM_VERSION(1, 3) && (header.flags & METADATA_FLAG_MASK) != 0 &&
      !draco::MetadataDecoder().DecodeGeometryMetadata(&buffer, &metadata))
    return std::nullopt;
  const auto offset = [&] { return bytes.size() - static_cast<uint64_t>(buffer.remaining_size()); };
  if (header.encoder_type == draco::POINT_CLOUD) {
    const uint64_t at = offset();
    int32_t count = 0;
    if (!buffer.Decode(&count)) return std::nullopt;
    return DeclaredPoints{count, at};
  }
  if (header.encoder_type != draco::TRIANGULAR_MESH ||
      header.encoder_method != draco::MESH_SEQUENTIAL_ENCODING)
    return std::nullopt;
  uint32_t faces = 0;
  uint32_t count = 0;
  const bool isFixedSize = version < DRACO_BITSTREAM_VERSION(2, 2);
  if (!(isFixedSize ? buffer.Decode(&faces) : draco::DecodeVarint(&faces, &buffer)))
    return std::nullopt;
  const uint64_t at = offset();
  if (!(isFixedSize ? buffer.Decode(&count) : draco::DecodeVarint(&count, &buffer)))
    return std::nullopt;
  return DeclaredPoints{count, at};
}

void checkDeclaredPoints(const InputStream& in, const std::vector<char>& bytes) {
  const std::optional<DeclaredPoints> declared = declaredPoints(bytes);
  if (!declared) return;
  if (declared->count < 0)
    in.failAt(declared->offset, fmt::format("negative point count {}", declared->count));
  const auto count = static_cast<uint64_t>(declared->count);
  if (count > kAlwaysAllowedPoints && count > kMaxPointsPerByte * bytes.size())
    in.failAt(declared->offset,
              fmt::format("the file declares {} points in {} bytes, more than the {} per byte this "
                          "reader accepts: the count is corrupt (decoding would exhaust memory)",
                          count, bytes.size(), kMaxPointsPerByte));
}

// Decode the whole file; the file's bytes are released on return, only the decoded cloud stays.
std::unique_ptr<draco::PointCloud> decodeFile(InputStream& in) {
  const std::vector<char> bytes = readWholeFile(in);
  checkDeclaredPoints(in, bytes);
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  draco::Decoder decoder;
  draco::StatusOr<std::unique_ptr<draco::PointCloud>> decoded =
      decoder.DecodePointCloudFromBuffer(&buffer);
  // Draco does not say where decoding failed; the offset is where its reading position stopped.
  if (!decoded.ok())
    in.failAt(bytes.size() - static_cast<uint64_t>(buffer.remaining_size()),
              "Draco cannot decode the file: " + decoded.status().error_msg_string());
  return std::move(decoded).value();
}

bool isNumeric(draco::DataType type) { return type >= draco::DT_INT8 && type <= draco::DT_FLOAT64; }

// Why the reader cannot use the attribute, or "" when it can: numeric values, at least three
// components, and a value for every point (else a point index would reach past the index map).
std::string unusableReason(const draco::PointAttribute& attribute, uint32_t pointCount) {
  if (!isNumeric(attribute.data_type())) return "its values are not numbers";
  if (attribute.num_components() < 3)
    return fmt::format("it has {} components, not 3", attribute.num_components());
  if (!attribute.is_mapping_identity() && attribute.indices_map_size() < pointCount)
    return fmt::format("it maps {} of {} points to values", attribute.indices_map_size(),
                       pointCount);
  return "";
}

// The attribute of this type, or nullptr when there is none or it is unusable; a file whose
// normals or colors cannot be read is read without them, as the PLY reader does.
const draco::PointAttribute* optionalAttribute(const draco::PointCloud& cloud,
                                               draco::GeometryAttribute::Type type) {
  const draco::PointAttribute* attribute = cloud.GetNamedAttribute(type);
  if (attribute == nullptr || !unusableReason(*attribute, cloud.num_points()).empty())
    return nullptr;
  return attribute;
}

const draco::PointAttribute& positionAttribute(const InputStream& in,
                                               const draco::PointCloud& cloud) {
  const draco::PointAttribute* position =
      cloud.GetNamedAttribute(draco::GeometryAttribute::POSITION);
  if (position == nullptr)
    throw FileError(in.name(), std::nullopt, "the Draco file has no POSITION attribute");
  const std::string reason = unusableReason(*position, cloud.num_points());
  if (!reason.empty())
    throw FileError(in.name(), std::nullopt, "the POSITION attribute is unusable: " + reason);
  return *position;
}

// Full intensity of color values converted to double: integer codes on the PLY scales (16-bit
// types 65535, other integers 255) unless Draco normalizes them; floats are 0–1.
double colorFullScale(const draco::PointAttribute& color) {
  if (!draco::IsDataTypeIntegral(color.data_type()) || color.normalized()) return 1.0;
  return draco::DataTypeLength(color.data_type()) == 2 ? 65535.0 : 255.0;
}

class DracoPointReader final : public PointReader {
 public:
  explicit DracoPointReader(InputStream in)
      : name_(in.name()),
        cloud_(decodeFile(in)),
        position_(&positionAttribute(in, *cloud_)),
        normal_(optionalAttribute(*cloud_, draco::GeometryAttribute::NORMAL)),
        color_(optionalAttribute(*cloud_, draco::GeometryAttribute::COLOR)) {
    if (color_ != nullptr) colorFullScale_ = colorFullScale(*color_);
    info_.path = in.path();
    info_.format = "draco";
    info_.declaredPoints = cloud_->num_points();
    info_.hasNormals = normal_ != nullptr;
    info_.hasColors = color_ != nullptr;
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    const uint32_t end =
        next_ + static_cast<uint32_t>(std::min<uint64_t>(maxPoints, cloud_->num_points() - next_));
    const size_t first = out.size();
    reserveBatch(out, end - next_);
    for (; next_ < end; ++next_) {
      const draco::PointIndex point(next_);
      const glm::dvec3 position = positionOf(point);
      if (!isFinite(position)) {
        ++stats_.droppedNonFinite;
        continue;
      }
      out.positions.push_back(position);
      if (normal_ != nullptr) out.normals.push_back(normalOf(point));
      if (color_ != nullptr) out.colors.push_back(colorOf(point));
    }
    stats_.pointsRead += out.size() - first;
    return out.size() - first;
  }

 private:
  void reserveBatch(PointCloud& out, size_t count) const {
    out.positions.reserve(out.size() + count);
    if (normal_ != nullptr) out.normals.reserve(out.size() + count);
    if (color_ != nullptr) out.colors.reserve(out.size() + count);
  }

  // The first three components of the point's value, converted by Draco (which also checks that
  // the value lies inside the attribute's buffer).
  std::array<double, 3> valueOf(const draco::PointAttribute& attribute,
                                draco::PointIndex point) const {
    std::array<double, 3> value{};
    if (!attribute.ConvertValue<double>(attribute.mapped_index(point), 3, value.data()))
      throw FileError(
          name_, std::nullopt,
          fmt::format("the {} value of point {} lies outside the decoded data",
                      draco::GeometryAttribute::TypeToString(attribute.attribute_type()),
                      point.value()));
    return value;
  }

  glm::dvec3 positionOf(draco::PointIndex point) const {
    const std::array<double, 3> value = valueOf(*position_, point);
    return {value[0], value[1], value[2]};
  }

  glm::vec3 normalOf(draco::PointIndex point) const {
    const std::array<double, 3> value = valueOf(*normal_, point);
    return {narrowToFloat(value[0]), narrowToFloat(value[1]), narrowToFloat(value[2])};
  }

  // Linear color: 8- and 16-bit codes through the sRGB table, other types through the formula.
  glm::vec3 colorOf(draco::PointIndex point) const {
    const std::array<float, 65536>& table = srgb16ToLinearTable();
    if (color_->data_type() == draco::DT_UINT8) {
      const std::array<uint8_t, 3> codes = codesOf<uint8_t>(point);
      return {table[codes[0] * 257u], table[codes[1] * 257u], table[codes[2] * 257u]};
    }
    if (color_->data_type() == draco::DT_UINT16) {
      const std::array<uint16_t, 3> codes = codesOf<uint16_t>(point);
      return {table[codes[0]], table[codes[1]], table[codes[2]]};
    }
    const std::array<double, 3> value = valueOf(*color_, point);
    return {linearFromSrgbScaled(value[0], colorFullScale_),
            linearFromSrgbScaled(value[1], colorFullScale_),
            linearFromSrgbScaled(value[2], colorFullScale_)};
  }

  // The raw integer codes of the point's color, whether or not Draco marks them normalized.
  template <typename T>
  std::array<T, 3> codesOf(draco::PointIndex point) const {
    std::array<T, 3> codes{};
    if (!color_->GetValue<T, 3>(color_->mapped_index(point), &codes))
      throw FileError(
          name_, std::nullopt,
          fmt::format("the COLOR value of point {} lies outside the decoded data", point.value()));
    return codes;
  }

  std::string name_;
  std::unique_ptr<draco::PointCloud> cloud_;
  const draco::PointAttribute* position_;
  const draco::PointAttribute* normal_;  // nullptr when the file has no usable normals
  const draco::PointAttribute* color_;   // nullptr when the file has no usable colors
  double colorFullScale_ = 1.0;
  uint32_t next_ = 0;  // the next point to convert
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::unique_ptr<PointReader> makeDracoReader(InputStream in) {
  return std::make_unique<DracoPointReader>(std::move(in));
}

}  // namespace iso::io
