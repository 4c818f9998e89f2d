// Points chunks: an 8-byte header and one Draco point cloud (specs/iso-format.md, "Points chunks").
#include "iso/points.h"

#include <draco/compression/decode.h>
#include <draco/compression/expert_encode.h>
#include <draco/compression/point_cloud/point_cloud_decoder.h>
#include <draco/core/decoder_buffer.h>
#include <draco/point_cloud/point_cloud_builder.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

#include "bytes.h"
#include "iso/check.h"
#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface.h"

namespace iso {
namespace {

using detail::loadLE;
using detail::storeLE;

struct AttributeRule {
  draco::GeometryAttribute::Type type;
  draco::DataType dataType;
  const char* name;
};
constexpr AttributeRule kPosition{draco::GeometryAttribute::POSITION, draco::DT_INT32,
                                  "POSITION int32"};
constexpr AttributeRule kColor{draco::GeometryAttribute::COLOR, draco::DT_UINT16, "COLOR uint16"};
constexpr AttributeRule kColor8{draco::GeometryAttribute::COLOR, draco::DT_UINT8, "COLOR uint8"};
constexpr AttributeRule kNormal{draco::GeometryAttribute::NORMAL, draco::DT_INT16, "NORMAL int16"};
constexpr AttributeRule kRadius{draco::GeometryAttribute::GENERIC, draco::DT_UINT16,
                                "GENERIC uint16"};

template <typename T>
void addAttribute(draco::PointCloudBuilder& builder, const AttributeRule& rule,
                  const std::vector<T>& values) {
  const int id = builder.AddAttribute(rule.type, int8_t(sizeof(T) / sizeof(values[0][0])),
                                      rule.dataType);
  builder.SetAttributeValuesForAllPoints(id, values.data(), sizeof(values[0]));
}

// The values of a decoded attribute, point by point (Draco may map points to shared values).
template <typename T, size_t N = 3>
std::vector<std::array<T, N>> valuesOf(const draco::PointAttribute& attribute, uint32_t count) {
  std::vector<std::array<T, N>> out(count);
  for (uint32_t i = 0; i < count; ++i)
    attribute.GetMappedValue(draco::PointIndex(i), out[i].data());
  return out;
}

// Whether the offsets along each axis span less than 2^31 (max - min <= 2^31 - 1): Draco's kd-tree
// coder codes them from their minimum in 31 bits.
bool withinSpan(const std::vector<std::array<int32_t, 3>>& offsets) {
  for (int a = 0; a < 3; ++a) {
    int64_t lo = std::numeric_limits<int64_t>::max(), hi = std::numeric_limits<int64_t>::min();
    for (const std::array<int32_t, 3>& o : offsets) {
      lo = std::min<int64_t>(lo, o[a]);
      hi = std::max<int64_t>(hi, o[a]);
    }
    if (!offsets.empty() && hi - lo > int64_t{kMaxPointOffsetSpan}) return false;
  }
  return true;
}

}  // namespace

std::vector<std::byte> encodePointsChunk(const PointsChunk& points, int speed) {
  const size_t n = points.size();
  if (n == 0 || n > kMaxPointsPerChunk)
    throw InternalError("a points chunk holds 1 to " + std::to_string(kMaxPointsPerChunk) +
                        " points, not " + std::to_string(n));
  if ((!points.colors.empty() && points.colors.size() != n) ||
      (!points.normals.empty() && points.normals.size() != n) ||
      (!points.radii.empty() && points.radii.size() != n))
    throw InternalError("points chunk attributes are not one per point");
  if (points.stepBits > kMaxPointStepBits)
    throw InternalError("points chunk step bits above " + std::to_string(kMaxPointStepBits));
  if (speed < 0 || speed > 10) throw InternalError("Draco speed must be 0 to 10");
  if (!withinSpan(points.offsets))
    throw InternalError("points chunk offsets span 2^31 or more along an axis");
  draco::PointCloudBuilder builder;
  builder.Start(uint32_t(n));
  addAttribute(builder, kPosition, points.offsets);
  if (!points.colors.empty()) {
    // Colors that are all 8-bit codes (v = 257 · c) go as bytes: the kd-tree coder codes every
    // bit of an attribute and cannot see that the low byte repeats the high one.
    const bool eightBit = std::all_of(
        points.colors.begin(), points.colors.end(),
        [](const auto& c) { return c[0] % 257 == 0 && c[1] % 257 == 0 && c[2] % 257 == 0; });
    if (eightBit) {
      std::vector<std::array<uint8_t, 3>> bytes(n);
      for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) bytes[i][a] = uint8_t(points.colors[i][a] / 257);
      addAttribute(builder, kColor8, bytes);
    } else {
      addAttribute(builder, kColor, points.colors);
    }
  }
  if (!points.normals.empty()) addAttribute(builder, kNormal, points.normals);
  if (!points.radii.empty()) {
    std::vector<std::array<uint16_t, 1>> radii(n);
    for (size_t i = 0; i < n; ++i) radii[i][0] = points.radii[i];
    addAttribute(builder, kRadius, radii);
  }
  const std::unique_ptr<draco::PointCloud> cloud = builder.Finalize(false);
  draco::ExpertEncoder encoder(*cloud);
  encoder.SetEncodingMethod(draco::POINT_CLOUD_KD_TREE_ENCODING);
  encoder.SetSpeedOptions(speed, speed);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeToBuffer(&buffer);
  if (!status.ok())
    throw std::runtime_error("Draco cannot encode a points chunk: " + status.error_msg_string());

  std::vector<std::byte> data(kPointsHeaderSize + buffer.size());
  storeLE<uint32_t>(data.data(), uint32_t(n));
  storeLE<uint8_t>(data.data() + 4, points.stepBits);
  storeLE<uint8_t>(data.data() + 5, uint8_t((points.colors.empty() ? 0 : kPointsHaveColors) |
                                            (points.normals.empty() ? 0 : kPointsHaveNormals) |
                                            (points.radii.empty() ? 0 : kPointsHaveRadii)));
  storeLE<uint16_t>(data.data() + 6, 0);
  std::memcpy(data.data() + kPointsHeaderSize, buffer.data(), buffer.size());
  return data;
}

namespace {

// The points of a chunk's data, checked against the rules of "Points chunks"; `fail` throws.
template <typename Fail>
PointsChunk decodePointsData(std::span<const std::byte> data, uint64_t tableCount,
                             const Fail& fail) {
  if (data.size() <= kPointsHeaderSize) fail("points data is shorter than its header");
  const uint32_t count = loadLE<uint32_t>(data.data());
  PointsChunk out;
  out.stepBits = loadLE<uint8_t>(data.data() + 4);
  const uint8_t attributes = loadLE<uint8_t>(data.data() + 5);
  if (count != tableCount)
    fail("points header says " + std::to_string(count) + " points, the chunk table " +
         std::to_string(tableCount));
  if (out.stepBits > kMaxPointStepBits)
    fail("step bits " + std::to_string(out.stepBits) + " above " +
         std::to_string(kMaxPointStepBits));
  if ((attributes & ~(kPointsHaveColors | kPointsHaveNormals | kPointsHaveRadii)) != 0 ||
      loadLE<uint16_t>(data.data() + 6) != 0)
    fail("reserved points header bits are not zero");

  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(data.data()) + kPointsHeaderSize,
              data.size() - kPointsHeaderSize);
  // Draco sizes its arrays by the count in its own header before reading a value: that count must
  // be the chunk's (bounded above) before anything is decoded.
  draco::DracoHeader header;
  if (!draco::PointCloudDecoder::DecodeHeader(&buffer, &header).ok() ||
      header.encoder_type != draco::POINT_CLOUD ||
      header.encoder_method != draco::POINT_CLOUD_KD_TREE_ENCODING ||
      (header.flags & METADATA_FLAG_MASK) != 0)
    fail("the points are not a Draco kd-tree point cloud without metadata");
  int32_t dracoCount = 0;
  if (!buffer.Decode(&dracoCount) || dracoCount != int32_t(count))
    fail("the Draco point count is not the chunk's");
  buffer.Init(reinterpret_cast<const char*>(data.data()) + kPointsHeaderSize,
              data.size() - kPointsHeaderSize);
  draco::Decoder decoder;
  draco::StatusOr<std::unique_ptr<draco::PointCloud>> decoded =
      decoder.DecodePointCloudFromBuffer(&buffer);
  if (!decoded.ok()) fail("Draco cannot decode the points: " + decoded.status().error_msg_string());
  const draco::PointCloud& cloud = *decoded.value();
  if (cloud.num_points() != count) fail("the Draco point cloud has another point count");
  const bool colors = (attributes & kPointsHaveColors) != 0;
  const bool normals = (attributes & kPointsHaveNormals) != 0;
  const bool radii = (attributes & kPointsHaveRadii) != 0;
  const int expected = 1 + int(colors) + int(normals) + int(radii);
  if (cloud.num_attributes() != expected)
    fail("the Draco point cloud has " + std::to_string(cloud.num_attributes()) +
         " attributes, the header says " + std::to_string(expected));
  const auto attribute = [&](const AttributeRule& rule,
                             int components = 3) -> const draco::PointAttribute& {
    const draco::PointAttribute* a = cloud.GetNamedAttribute(rule.type);
    if (a == nullptr || cloud.NumNamedAttributes(rule.type) != 1 ||
        a->data_type() != rule.dataType || a->num_components() != components ||
        (!a->is_mapping_identity() && a->indices_map_size() < count))
      fail("the Draco point cloud has no single " + std::to_string(components) + "-component " +
           rule.name + " attribute");
    return *a;
  };
  out.offsets = valuesOf<int32_t>(attribute(kPosition), count);
  if (!withinSpan(out.offsets)) fail("the offsets span 2^31 or more along an axis");
  if (colors) {
    const draco::PointAttribute* c = cloud.GetNamedAttribute(draco::GeometryAttribute::COLOR);
    if (c != nullptr && c->data_type() == draco::DT_UINT8) {
      for (const std::array<uint8_t, 3>& v : valuesOf<uint8_t>(attribute(kColor8), count))
        out.colors.push_back({uint16_t(v[0] * 257), uint16_t(v[1] * 257), uint16_t(v[2] * 257)});
    } else {
      out.colors = valuesOf<uint16_t>(attribute(kColor), count);
    }
  }
  if (normals) {
    out.normals = valuesOf<int16_t>(attribute(kNormal), count);
    for (const std::array<int16_t, 3>& n : out.normals)
      for (int16_t c : n)
        if (c == -32768) fail("a normal component is -32768, which snorm16 does not use");
  }
  if (radii)
    for (const std::array<uint16_t, 1>& r : valuesOf<uint16_t, 1>(attribute(kRadius, 1), count))
      out.radii.push_back(r[0]);
  return out;
}

// Points chunk rows compared attribute by attribute (the attributes a chunk lacks are empty).
struct RowLess {
  const PointsChunk& c;
  bool operator()(uint32_t a, uint32_t b) const {
    if (c.offsets[a] != c.offsets[b]) return c.offsets[a] < c.offsets[b];
    if (!c.colors.empty() && c.colors[a] != c.colors[b]) return c.colors[a] < c.colors[b];
    if (!c.normals.empty() && c.normals[a] != c.normals[b]) return c.normals[a] < c.normals[b];
    if (!c.radii.empty()) return c.radii[a] < c.radii[b];
    return false;
  }
};

std::vector<uint32_t> rowOrder(const PointsChunk& c) {
  std::vector<uint32_t> order(c.size());
  for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), RowLess{c});
  return order;
}

}  // namespace

PointsChunk decodePointsChunk(const Reader& reader, uint32_t id) {
  const ChunkInfo& chunk = reader.chunk(id);
  const auto fail = [&](const std::string& reason) {
    throw FileError(reader.name(), chunk.offset, "chunk " + std::to_string(id) + ": " + reason);
  };
  if (chunk.kind != kPointsKind && chunk.kind != kVolumePointsKind) fail("not a points chunk");
  // The table entry's rules were checked when the file was opened. Draco decodes most damaged
  // streams into other points without complaint: the payload's checksum, which payload() checks,
  // is what tells.
  const ChunkData payload = reader.payload(id);
  return decodePointsData(payload.bytes(), chunk.pointCount, fail);
}

std::vector<uint32_t> decodedPointOrder(std::span<const std::byte> data,
                                        const PointsChunk& points) {
  const PointsChunk decoded = decodePointsData(data, points.size(), [](const std::string& why) {
    throw InternalError("a points chunk just encoded does not decode: " + why);
  });
  const std::vector<uint32_t> byRowIn = rowOrder(points), byRowOut = rowOrder(decoded);
  std::vector<uint32_t> order(points.size());
  for (size_t i = 0; i < order.size(); ++i) order[byRowOut[i]] = byRowIn[i];
  return order;
}

double PointValues::value(size_t i) const {
  return missing && codes[i] == kNoValue ? std::numeric_limits<double>::quiet_NaN()
                                         : offset + double(codes[i]) * step;
}

namespace {

// Why a value name is not one the format allows; empty when it is.
std::string nameProblem(std::string_view name) {
  if (name.empty() || name.size() > kMaxValueNameBytes)
    return "a value name has 1 to " + std::to_string(kMaxValueNameBytes) + " bytes";
  if (name.find('\0') != std::string_view::npos) return "a value name has a zero byte";
  return {};
}

}  // namespace

PointValues quantizeValues(std::string name, uint32_t pointsChunk,
                           std::span<const double> values) {
  if (const std::string problem = nameProblem(name); !problem.empty())
    throw InternalError(problem + ": '" + name + "'");
  if (values.empty() || values.size() > kMaxPointsPerChunk)
    throw InternalError("a values chunk holds 1 to 2^20 values");
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  bool integers = true;
  for (double v : values) {
    if (!std::isfinite(v)) continue;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
    integers = integers && v == std::floor(v);
  }
  PointValues out;
  out.name = std::move(name);
  out.pointsChunk = pointsChunk;
  out.missing = std::any_of(values.begin(), values.end(), [](double v) { return !std::isfinite(v); });
  out.codes.resize(values.size(), kNoValue);
  if (!(lo <= hi)) return out;  // no finite value
  if (!std::isfinite(hi - lo)) throw InternalError("values span more than a double holds");
  const double top = double(out.missing ? kNoValue - 1 : kNoValue);
  out.offset = lo;
  out.step = (integers && hi - lo <= top) || hi == lo ? 1.0 : (hi - lo) / top;
  for (size_t i = 0; i < values.size(); ++i)
    if (std::isfinite(values[i]))
      out.codes[i] = uint16_t(std::clamp(std::round((values[i] - lo) / out.step), 0.0, top));
  return out;
}

std::vector<std::byte> encodeValuesChunk(const PointValues& v) {
  if (const std::string problem = nameProblem(v.name); !problem.empty())
    throw InternalError(problem);
  if (v.codes.empty() || v.codes.size() > kMaxPointsPerChunk || !std::isfinite(v.offset) ||
      !(v.step > 0.0) || !std::isfinite(v.offset + double(kNoValue) * v.step))
    throw InternalError("values the format does not allow");
  std::vector<std::byte> data(kValuesHeaderSize + 2 * v.codes.size());
  storeLE<uint32_t>(data.data(), v.pointsChunk);
  storeLE<uint32_t>(data.data() + 4, uint32_t(v.codes.size()));
  storeLE<double>(data.data() + 8, v.offset);
  storeLE<double>(data.data() + 16, v.step);
  storeLE<uint8_t>(data.data() + 24, v.missing ? 1 : 0);
  std::memcpy(data.data() + 32, v.name.data(), v.name.size());
  for (size_t i = 0; i < v.codes.size(); ++i)
    storeLE<uint16_t>(data.data() + kValuesHeaderSize + 2 * i, v.codes[i]);
  return data;
}

PointValues decodeValuesChunk(const Reader& reader, uint32_t id) {
  const ChunkInfo& chunk = reader.chunk(id);
  const auto fail = [&](const std::string& reason) {
    throw FileError(reader.name(), chunk.offset, "chunk " + std::to_string(id) + ": " + reason);
  };
  if (chunk.kind != kValuesKind) fail("not a values chunk");
  const ChunkData payload = reader.payload(id);
  const std::span<const std::byte> data = payload.bytes();
  if (data.size() < kValuesHeaderSize) fail("values data is shorter than its header");
  PointValues out;
  out.pointsChunk = loadLE<uint32_t>(data.data());
  const uint32_t count = loadLE<uint32_t>(data.data() + 4);
  out.offset = loadLE<double>(data.data() + 8);
  out.step = loadLE<double>(data.data() + 16);
  const uint8_t flags = loadLE<uint8_t>(data.data() + 24);
  out.missing = (flags & 1) != 0;
  if ((flags & ~1) != 0) fail("reserved values header bits are not zero");
  for (size_t i = 25; i < 32; ++i)
    if (data[i] != std::byte{0}) fail("reserved values header bytes are not zero");
  const char* name = reinterpret_cast<const char*>(data.data() + 32);
  out.name.assign(name, strnlen(name, kMaxValueNameBytes));
  for (size_t i = 32 + out.name.size(); i < kValuesHeaderSize; ++i)
    if (data[i] != std::byte{0}) fail("the value name's padding is not zero");
  if (out.name.empty()) fail("the value name is empty");
  if (out.pointsChunk >= reader.chunks().size() ||
      (reader.chunk(out.pointsChunk).kind != kPointsKind &&
       reader.chunk(out.pointsChunk).kind != kVolumePointsKind))
    fail("values of chunk " + std::to_string(out.pointsChunk) + ", which is not a points chunk");
  const ChunkInfo& points = reader.chunk(out.pointsChunk);
  if (count != chunk.pointCount || count != points.pointCount)
    fail("values header says " + std::to_string(count) + " values, the chunk table " +
         std::to_string(chunk.pointCount) + ", its points chunk " +
         std::to_string(points.pointCount));
  if (chunk.level != points.level || chunk.key != points.key)
    fail("the values chunk's cell is not its points chunk's");
  if (data.size() != kValuesHeaderSize + 2 * uint64_t{count})
    fail("values data is not its header and 2 bytes a value");
  if (!std::isfinite(out.offset) || !(out.step > 0.0) ||
      !std::isfinite(out.offset + double(kNoValue) * out.step))
    fail("the values' offset and step are not finite, or the step is not positive");
  out.codes.resize(count);
  for (size_t i = 0; i < count; ++i)
    out.codes[i] = loadLE<uint16_t>(data.data() + kValuesHeaderSize + 2 * i);
  return out;
}

uint16_t encodePointRadius(double radius) {
  if (!(radius < 1.0)) return 0;  // NaN too
  if (!(radius > 0x1p-64)) return 65535;
  // The largest code whose radius is at least `radius` (codes fall as radii grow).
  double code = std::floor(-1024.0 * std::log2(radius));
  while (code > 0 && decodePointRadius(uint16_t(code)) < radius) code -= 1;
  return uint16_t(std::clamp(code, 0.0, 65535.0));
}

double decodePointRadius(uint16_t code) { return std::exp2(-double(code) / 1024.0); }

double densityPointRadius(uint8_t level, uint64_t count) {
  return 2.0 * std::ldexp(1.0, -int(level)) / std::sqrt(double(std::max<uint64_t>(count, 1)));
}

std::vector<bool> subsampleChunks(const Reader& reader) {
  std::vector<bool> parent(reader.chunks().size(), false);
  for (const ChunkInfo& c : reader.chunks())
    if (c.kind == kPointsKind && c.parent != kNoParent) parent[c.parent] = true;
  return parent;
}

std::array<double, 3> pointFramePosition(uint8_t level, uint64_t key, uint8_t stepBits,
                                         const std::array<int32_t, 3>& offset) {
  const std::array<uint32_t, 3> cell = mortonDecode(key);
  std::array<double, 3> out{};
  for (int a = 0; a < 3; ++a)
    out[a] =
        std::ldexp(double(cell[a]), -int(level)) + std::ldexp(double(offset[a]), -int(stepBits));
  return out;
}

}  // namespace iso
