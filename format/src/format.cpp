// Attribute schema and frame rules, and names (specs/iso-format.md, "Header", "AttributeDesc").
#include "iso/format.h"

#include <cmath>

namespace iso {
namespace {

// Whether an encoding may carry a semantic with the given component count.
bool isAllowedEncoding(Semantic semantic, Encoding encoding, uint8_t components) {
  switch (semantic) {
    case Semantic::SignedDistance:
      return components == 1 && (encoding == Encoding::Snorm8 || encoding == Encoding::Snorm16 ||
                                 encoding == Encoding::Float32);
    case Semantic::Normal:
      return (components == 2 && (encoding == Encoding::Oct16 || encoding == Encoding::Oct24)) ||
             (components == 3 && encoding == Encoding::Float32);
    case Semantic::Color:
      return components == 3 && (encoding == Encoding::Srgb8 || encoding == Encoding::Float32);
    case Semantic::Occlusion:
      return components == 1 && (encoding == Encoding::Unorm8 || encoding == Encoding::Float32);
  }
  return false;
}

bool isKnownSemantic(Semantic s) {
  return s >= Semantic::SignedDistance && s <= Semantic::Occlusion;
}

bool isKnownEncoding(Encoding e) { return e >= Encoding::Snorm8 && e <= Encoding::Float32; }

}  // namespace

std::string_view attributeSchemaProblem(const std::vector<AttributeDesc>& attributes) {
  if (attributes.empty()) return "the attribute schema is empty";
  if (attributes.size() > kMaxAttributes) return "the attribute schema has more than 8 attributes";
  if (attributes[0].semantic != Semantic::SignedDistance)
    return "the first attribute is not signed_distance";
  unsigned seen = 0;
  for (const AttributeDesc& a : attributes) {
    if (!isKnownSemantic(a.semantic)) return "unknown attribute semantic";
    if (!isKnownEncoding(a.encoding)) return "unknown attribute encoding";
    const unsigned bit = 1u << static_cast<unsigned>(a.semantic);
    if (seen & bit) return "an attribute semantic appears twice";
    seen |= bit;
    if (!isAllowedEncoding(a.semantic, a.encoding, a.components))
      return "attribute encoding or component count not allowed for its semantic";
    if (a.semantic == Semantic::SignedDistance) {
      if (!std::isfinite(a.scale) || !(a.scale > 0.0f))
        return "signed_distance scale must be finite and positive";
    } else if (a.scale != 0.0f || std::signbit(a.scale)) {
      return "attribute scale must be 0 for this semantic";
    }
  }
  return {};
}

std::optional<FrameProblem> frameProblem(const Frame& frame) {
  for (int axis = 0; axis < 3; ++axis)
    if (!std::isfinite(frame.origin[axis])) return FrameProblem{axis, "frame origin is not finite"};
  if (!(frame.size >= kMinFrameSize && frame.size <= kMaxFrameSize))
    return FrameProblem{3, "frame size is not within 2^-64 to 2^64"};
  for (int axis = 0; axis < 3; ++axis)
    if (!(std::abs(frame.origin[axis]) <= kMaxFrameOriginInSizes * frame.size))
      return FrameProblem{axis, "frame origin is more than 2^31 frame sizes from 0"};
  return std::nullopt;
}

uint32_t encodedSize(const AttributeDesc& a) {
  switch (a.encoding) {
    case Encoding::Snorm8:
    case Encoding::Srgb8:
    case Encoding::Unorm8:
      return a.components;
    case Encoding::Snorm16:
      return 2u * a.components;
    case Encoding::Oct16:
      return 2;
    case Encoding::Oct24:
      return 3;
    case Encoding::Float32:
      return 4u * a.components;
  }
  return 0;
}

std::string_view semanticName(Semantic semantic) {
  switch (semantic) {
    case Semantic::SignedDistance:
      return "signed_distance";
    case Semantic::Normal:
      return "normal";
    case Semantic::Color:
      return "color";
    case Semantic::Occlusion:
      return "occlusion";
  }
  return "unknown";
}

std::string_view encodingName(Encoding encoding) {
  switch (encoding) {
    case Encoding::Snorm8:
      return "snorm8";
    case Encoding::Snorm16:
      return "snorm16";
    case Encoding::Oct16:
      return "oct16";
    case Encoding::Oct24:
      return "oct24";
    case Encoding::Srgb8:
      return "srgb8";
    case Encoding::Unorm8:
      return "unorm8";
    case Encoding::Float32:
      return "float32";
  }
  return "unknown";
}

std::string_view codecName(Codec codec) {
  switch (codec) {
    case Codec::Raw:
      return "raw";
    case Codec::Zstd:
      return "zstd";
  }
  return "unknown";
}

std::string_view chunkKindName(uint8_t kind) {
  switch (static_cast<ChunkKind>(kind)) {
    case ChunkKind::Blob:
      return "blob";
    case ChunkKind::Surface:
      return "surface";
    case ChunkKind::Points:
      return "points";
    case ChunkKind::Values:
      return "values";
    case ChunkKind::VolumePoints:
      return "volume points";
    case ChunkKind::Lighting:
      return "lighting";
  }
  return "unknown";
}

}  // namespace iso
