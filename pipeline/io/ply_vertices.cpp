#include "pipeline/io/ply_vertices.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <string_view>
#include <type_traits>

#include "iso/check.h"
#include "iso/error.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/text_fields.h"

namespace iso::io {
namespace {

// Records gathered at a time when lists interleave the vertex properties.
constexpr size_t kGatherRecords = 4096;

// Property names of each slot, in the order of PlyVertexDecoder::Slot.
const std::array<std::vector<std::string_view>, 9> kSlotNames = {{{"x"},
                                                                  {"y"},
                                                                  {"z"},
                                                                  {"nx", "normal_x"},
                                                                  {"ny", "normal_y"},
                                                                  {"nz", "normal_z"},
                                                                  {"red", "r", "diffuse_red"},
                                                                  {"green", "g", "diffuse_green"},
                                                                  {"blue", "b", "diffuse_blue"}}};

double colorFullScale(PlyType type) {
  switch (type) {
    case PlyType::Int16:
    case PlyType::UInt16:
      return 65535.0;
    case PlyType::Float32:
    case PlyType::Float64:
      return 1.0;
    default:
      return 255.0;
  }
}

std::optional<size_t> findScalar(const PlyElement& element,
                                 const std::vector<std::string_view>& names) {
  for (size_t i = 0; i < element.properties.size(); ++i)
    if (!element.properties[i].isList() &&
        std::find(names.begin(), names.end(), element.properties[i].name) != names.end())
      return i;
  return std::nullopt;
}

// Parse an ASCII value; a float property is rounded to float directly, as if it had been binary.
bool parseValue(PlyType type, std::string_view text, double& value) {
  if (type != PlyType::Float32) return parseNumber(text, value);
  float single = 0.0f;
  if (!parseNumber(text, single)) return false;
  value = single;
  return true;
}

// Call f with a value of the C++ type of a PLY type, so that decoders dispatch once per column.
template <typename F>
void visitPlyType(PlyType type, F&& f) {
  switch (type) {
    case PlyType::Int8:
      return f(int8_t{});
    case PlyType::UInt8:
      return f(uint8_t{});
    case PlyType::Int16:
      return f(int16_t{});
    case PlyType::UInt16:
      return f(uint16_t{});
    case PlyType::Int32:
      return f(int32_t{});
    case PlyType::UInt32:
      return f(uint32_t{});
    case PlyType::Float32:
      return f(float{});
    case PlyType::Float64:
      return f(double{});
  }
}

// Decode one scalar property of `count` records (`stride` bytes apart from p) into a member of each
// output vector. Decoding column by column dispatches on the type once per batch, not per value.
template <bool kBigEndian, typename T, typename Vec>
void decodeColumnAs(const std::byte* p, size_t count, size_t stride, Vec* out,
                    typename Vec::value_type Vec::*member) {
  using Out = typename Vec::value_type;
  for (size_t i = 0; i < count; ++i, p += stride) {
    const T value = loadPlyRaw<kBigEndian, T>(p);
    if constexpr (std::is_same_v<Out, float> && std::is_same_v<T, double>) {
      out[i].*member = narrowToFloat(value);
    } else {
      out[i].*member = static_cast<Out>(value);
    }
  }
}

template <bool kBigEndian, typename Vec>
void decodeColumn(PlyType type, const std::byte* p, size_t count, size_t stride, Vec* out,
                  typename Vec::value_type Vec::*member) {
  visitPlyType(type, [&](auto zero) {
    decodeColumnAs<kBigEndian, decltype(zero)>(p, count, stride, out, member);
  });
}

// Decode one scalar property of `count` records into doubles `outStride` apart (an extra).
template <bool kBigEndian>
void decodeExtraColumn(PlyType type, const std::byte* p, size_t count, size_t stride, double* out,
                       size_t outStride) {
  visitPlyType(type, [&](auto zero) {
    using T = decltype(zero);
    for (size_t i = 0; i < count; ++i, p += stride, out += outStride)
      *out = static_cast<double>(loadPlyRaw<kBigEndian, T>(p));
  });
}

// Decode one color channel of `count` records to linear values; integer codes through the table.
template <bool kBigEndian>
void decodeColorColumn(PlyType type, double fullScale, const std::byte* p, size_t count,
                       size_t stride, glm::vec3* out, float glm::vec3::*member) {
  const std::array<float, 65536>& table = srgb16ToLinearTable();
  if (type == PlyType::UInt8) {
    for (size_t i = 0; i < count; ++i, p += stride)
      out[i].*member = table[size_t{loadPlyRaw<kBigEndian, uint8_t>(p)} * 257];
  } else if (type == PlyType::UInt16) {
    for (size_t i = 0; i < count; ++i, p += stride)
      out[i].*member = table[loadPlyRaw<kBigEndian, uint16_t>(p)];
  } else {
    for (size_t i = 0; i < count; ++i, p += stride)
      out[i].*member = linearFromSrgbScaled(loadPlyScalar<kBigEndian>(type, p), fullScale);
  }
}

}  // namespace

PlyVertexDecoder::PlyVertexDecoder(const InputStream& in, PlyEncoding encoding,
                                   const PlyElement& vertex, bool keepNonFinite, bool keepExtras)
    : encoding_(encoding),
      element_(vertex),
      targetOfProperty_(vertex.properties.size(), -1),
      recordBytes_(vertex.scalarBytes()),
      keepNonFinite_(keepNonFinite),
      remaining_(vertex.count) {
  std::array<std::optional<size_t>, kSlotCount> found;
  for (size_t slot = 0; slot < kSlotCount; ++slot)
    found[slot] = findScalar(vertex, kSlotNames[slot]);
  for (size_t slot = kX; slot <= kZ; ++slot)
    if (!found[slot])
      throw FileError(
          in.name(), std::nullopt,
          fmt::format("the vertex element has no scalar property '{}'", kSlotNames[slot][0]));
  hasNormals_ = found[kNx] && found[kNy] && found[kNz];
  hasColors_ = found[kRed] && found[kGreen] && found[kBlue];

  std::vector<size_t> offsets(vertex.properties.size(), 0);
  for (size_t i = 0, offset = 0; i < vertex.properties.size(); ++i) {
    offsets[i] = offset;
    if (!vertex.properties[i].isList()) offset += plyTypeSize(vertex.properties[i].type);
  }
  for (size_t slot = 0; slot < kSlotCount; ++slot) {
    const bool isUsed = slot <= kZ || (slot <= kNz ? hasNormals_ : hasColors_);
    if (!isUsed) continue;
    const size_t property = *found[slot];
    const PlyType type = vertex.properties[property].type;
    sources_[slot] = {type, offsets[property], colorFullScale(type)};
    targetOfProperty_[property] = static_cast<int32_t>(slot);
  }
  if (keepExtras) findExtras(vertex, offsets);
}

void PlyVertexDecoder::findExtras(const PlyElement& vertex, const std::vector<size_t>& offsets) {
  for (size_t i = 0; i < vertex.properties.size(); ++i) {
    const PlyProperty& property = vertex.properties[i];
    if (property.isList() || targetOfProperty_[i] >= 0) continue;
    targetOfProperty_[i] = static_cast<int32_t>(kSlotCount + extraSources_.size());
    extraSources_.push_back({property.type, offsets[i], 1.0});
    extraNames_.push_back(property.name);
  }
}

// The names describe the layout of out.extras, so they can change only while out holds no point.
void PlyVertexDecoder::adoptExtraNames(PointCloud& out) const {
  if (out.extraNames == extraNames_) return;
  ISO_CHECK(out.size() == 0);
  out.extraNames = extraNames_;
  out.extras.clear();
}

void PlyVertexDecoder::failEndsEarly(const InputStream& in) const {
  in.fail(fmt::format("file ends after {} of {} vertices", element_.count - remaining_,
                      element_.count));
}

size_t PlyVertexDecoder::decode(InputStream& in, PointCloud& out, size_t maxRecords) {
  maxRecords = static_cast<size_t>(std::min<uint64_t>(maxRecords, remaining_));
  if (maxRecords == 0) return 0;
  adoptExtraNames(out);
  if (encoding_ == PlyEncoding::Ascii) return decodeAscii(in, out, maxRecords);
  if (element_.hasLists()) return decodeBinaryWithLists(in, out, maxRecords);
  return decodeBinary(in, out, maxRecords);
}

size_t PlyVertexDecoder::decodeBinary(InputStream& in, PointCloud& out, size_t maxRecords) {
  size_t done = 0;
  while (done < maxRecords) {
    const std::span<const std::byte> bytes = in.peek(recordBytes_);
    if (bytes.size() < recordBytes_) failEndsEarly(in);
    const size_t count = std::min(bytes.size() / recordBytes_, maxRecords - done);
    appendRecords(bytes.data(), count, out);
    in.consume(count * recordBytes_);
    done += count;
    remaining_ -= count;
  }
  return done;
}

size_t PlyVertexDecoder::decodeBinaryWithLists(InputStream& in, PointCloud& out,
                                               size_t maxRecords) {
  const size_t count = std::min(maxRecords, kGatherRecords);
  scratch_.resize(count * recordBytes_);
  std::byte* record = scratch_.data();
  for (size_t i = 0; i < count; ++i, record += recordBytes_) {
    size_t offset = 0;
    for (const PlyProperty& property : element_.properties) {
      if (property.isList()) {
        const uint64_t bytes =
            readPlyListCount(in, encoding_, *property.countType) * plyTypeSize(property.type);
        if (in.skip(bytes) != bytes) failEndsEarly(in);
        continue;
      }
      if (!in.readExact(record + offset, plyTypeSize(property.type))) failEndsEarly(in);
      offset += plyTypeSize(property.type);
    }
    --remaining_;
  }
  appendRecords(scratch_.data(), count, out);
  return count;
}

void PlyVertexDecoder::appendRecords(const std::byte* records, size_t count, PointCloud& out) {
  if (encoding_ == PlyEncoding::BinaryBigEndian) return appendRecordsAs<true>(records, count, out);
  appendRecordsAs<false>(records, count, out);
}

template <bool kBigEndian>
void PlyVertexDecoder::appendRecordsAs(const std::byte* records, size_t count, PointCloud& out) {
  static constexpr double glm::dvec3::*kPositionMembers[] = {&glm::dvec3::x, &glm::dvec3::y,
                                                             &glm::dvec3::z};
  static constexpr float glm::vec3::*kMembers[] = {&glm::vec3::x, &glm::vec3::y, &glm::vec3::z};
  const size_t first = out.positions.size();
  out.positions.resize(first + count);
  for (int axis = 0; axis < 3; ++axis) {
    const SlotSource& source = sources_[kX + axis];
    decodeColumn<kBigEndian>(source.type, records + source.offset, count, recordBytes_,
                             out.positions.data() + first, kPositionMembers[axis]);
  }
  if (hasNormals_) {
    out.normals.resize(first + count);
    for (int axis = 0; axis < 3; ++axis) {
      const SlotSource& source = sources_[kNx + axis];
      decodeColumn<kBigEndian>(source.type, records + source.offset, count, recordBytes_,
                               out.normals.data() + first, kMembers[axis]);
    }
  }
  if (hasColors_) {
    out.colors.resize(first + count);
    for (int channel = 0; channel < 3; ++channel) {
      const SlotSource& source = sources_[kRed + channel];
      decodeColorColumn<kBigEndian>(source.type, source.fullScale, records + source.offset, count,
                                    recordBytes_, out.colors.data() + first, kMembers[channel]);
    }
  }
  const size_t extraCount = extraSources_.size();
  if (extraCount > 0) {
    out.extras.resize((first + count) * extraCount);
    for (size_t extra = 0; extra < extraCount; ++extra) {
      const SlotSource& source = extraSources_[extra];
      decodeExtraColumn<kBigEndian>(source.type, records + source.offset, count, recordBytes_,
                                    out.extras.data() + first * extraCount + extra, extraCount);
    }
  }
  if (!keepNonFinite_) dropped_ += removeNonFinite(out, first);
}

size_t PlyVertexDecoder::decodeAscii(InputStream& in, PointCloud& out, size_t maxRecords) {
  std::vector<double> values(kSlotCount + extraSources_.size());
  std::string_view line;
  std::string_view field;
  size_t done = 0;
  while (done < maxRecords) {
    if (!in.readLine(line)) failEndsEarly(in);
    std::string_view rest = line;
    if (!nextField<isBlank>(rest, field)) continue;  // a blank line
    rest = line;
    for (size_t i = 0; i < element_.properties.size(); ++i) {
      const PlyProperty& property = element_.properties[i];
      if (!nextField<isBlank>(rest, field))
        in.failLine(fmt::format("the vertex has no value for property '{}'", property.name));
      if (property.isList()) {
        int64_t length = 0;
        if (!parseInteger(field, length) || length < 0)
          in.failLine(
              fmt::format("invalid list length '{}' for property '{}'", field, property.name));
        for (int64_t item = 0; item < length; ++item)
          if (!nextField<isBlank>(rest, field))
            in.failLine(fmt::format("list '{}' ends early", property.name));
        continue;
      }
      const int32_t target = targetOfProperty_[i];
      if (target >= 0 && !parseValue(property.type, field, values[size_t(target)]))
        in.failLine(fmt::format("property '{}' is not a number: '{}'", property.name, field));
    }
    if (nextField<isBlank>(rest, field))
      in.failLine(
          fmt::format("more values than the {} vertex properties", element_.properties.size()));
    appendValues(values, out);
    ++done;
    --remaining_;
  }
  return done;
}

void PlyVertexDecoder::appendValues(const std::vector<double>& values, PointCloud& out) {
  const glm::dvec3 position{values[kX], values[kY], values[kZ]};
  if (!keepNonFinite_ && !isFinite(position)) {
    ++dropped_;
    return;
  }
  out.positions.push_back(position);
  if (hasNormals_)
    out.normals.emplace_back(narrowToFloat(values[kNx]), narrowToFloat(values[kNy]),
                             narrowToFloat(values[kNz]));
  if (hasColors_) {
    const auto color = [&](Slot slot) {
      return linearFromSrgbScaled(values[slot], sources_[slot].fullScale);
    };
    out.colors.emplace_back(color(kRed), color(kGreen), color(kBlue));
  }
  // A float property's text is rounded to float, as if it were binary.
  for (size_t extra = 0; extra < extraSources_.size(); ++extra) {
    const double value = values[kSlotCount + extra];
    out.extras.push_back(extraSources_[extra].type == PlyType::Float32
                             ? double(narrowToFloat(value))
                             : value);
  }
}

}  // namespace iso::io
