// The .iso container: version constants, structure sizes and the in-memory form of its header
// and chunk table. The byte layout of every structure is specified in specs/iso-format.md.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

namespace iso {

// Format version (specs/iso-format.md, "Change log"). Readers accept any minor version of their
// major version; a change that older readers cannot ignore increases the major version. This
// reader also reads every 1.x file: each is a valid 2.0 file.
inline constexpr uint16_t kFormatMajor = 2;
inline constexpr uint16_t kFormatMinor = 2;
inline constexpr uint16_t kOldestFormatMajor = 1;

inline constexpr std::array<uint8_t, 8> kHeaderMagic = {0x89, 'I',  'S',  'O',
                                                        0x0D, 0x0A, 0x1A, 0x0A};
inline constexpr std::array<uint8_t, 8> kTrailerMagic = {0x89, 'I', 'S', 'O', 'E', 'N', 'D', 0x0A};

inline constexpr uint32_t kHeaderSize = 256;
inline constexpr uint32_t kTrailerSize = 64;
inline constexpr uint32_t kChunkEntrySize = 80;
inline constexpr uint32_t kMaxAttributes = 8;
inline constexpr uint32_t kNoParent = 0xFFFFFFFFu;
inline constexpr uint8_t kMaxLevel = 21;
inline constexpr uint64_t kMaxChunkRawSize = uint64_t{1} << 30;
inline constexpr uint8_t kMinPayloadAlignmentLog2 = 3;
inline constexpr uint8_t kMaxPayloadAlignmentLog2 = 16;
inline constexpr uint8_t kDefaultPayloadAlignmentLog2 = 12;
// The frame's limits (specs/iso-format.md, "Header"): its size is 2^-64 to 2^64 world units, so
// that it and its finest cells (2^-21 of it) are normal binary32 numbers; each origin component is
// at most 2^31 sizes from 0, so that binary64 world coordinates of the cube still tell its finest
// cells apart.
inline constexpr double kMinFrameSize = 0x1p-64;
inline constexpr double kMaxFrameSize = 0x1p64;
inline constexpr double kMaxFrameOriginInSizes = 0x1p31;
// The most input points the surface chunks without a surface parent may count together
// (specs/iso-format.md, "Chunk table"): counts stay exact in binary64.
inline constexpr uint64_t kMaxPointCount = uint64_t{1} << 53;
// The most bytes one stored byte of a zstd payload can decode to: a 4-byte RLE block gives at
// most 128 KiB (specs/iso-format.md, "Payloads").
inline constexpr uint64_t kMaxZstdRatio = 32768;

enum class Semantic : uint8_t { SignedDistance = 1, Normal = 2, Color = 3, Occlusion = 4 };

enum class Encoding : uint8_t {
  Snorm8 = 1,
  Snorm16 = 2,
  Oct16 = 3,
  Oct24 = 4,
  Srgb8 = 5,
  Unorm8 = 6,
  Float32 = 7,
};

enum class Codec : uint8_t { Raw = 0, Zstd = 1 };

// Values (3) and VolumePoints (4) since 2.1, Lighting (5) since 2.2.
enum class ChunkKind : uint8_t {
  Blob = 0,
  Surface = 1,
  Points = 2,
  Values = 3,
  VolumePoints = 4,
  Lighting = 5
};

// One corner attribute and its quantization.
struct AttributeDesc {
  Semantic semantic = Semantic::SignedDistance;
  Encoding encoding = Encoding::Snorm8;
  uint8_t components = 1;
  float scale = 0.0f;  // signed_distance: distance of value 1.0 in node diagonals; else 0

  bool operator==(const AttributeDesc&) const = default;
};

// The world placement of the octree root cube; everything else in a file is relative to it.
struct Frame {
  std::array<double, 3> origin = {0.0, 0.0, 0.0};
  double size = 1.0;

  bool operator==(const Frame&) const = default;
};

// A schema with the signed distance alone, snorm8, covering one node diagonal.
inline std::vector<AttributeDesc> signedDistanceOnlySchema() {
  std::vector<AttributeDesc> schema(1);
  schema[0].scale = 1.0f;
  return schema;
}

struct FileHeader {
  uint16_t versionMajor = kFormatMajor;
  uint16_t versionMinor = kFormatMinor;
  uint32_t flags = 0;
  uint8_t payloadAlignmentLog2 = kDefaultPayloadAlignmentLog2;
  uint8_t maxLevel = 0;
  Frame frame;
  std::vector<AttributeDesc> attributes = signedDistanceOnlySchema();

  uint64_t payloadAlignment() const { return uint64_t{1} << payloadAlignmentLog2; }
  bool operator==(const FileHeader&) const = default;
};

// One chunk table entry (specs/iso-format.md, "Chunk table").
struct ChunkInfo {
  uint64_t offset = 0;
  uint64_t storedSize = 0;
  uint64_t rawSize = 0;
  uint64_t checksum = 0;
  uint64_t key = 0;
  uint64_t pointCount = 0;
  uint32_t id = 0;
  uint32_t parent = kNoParent;
  uint32_t nodeCount = 0;
  uint32_t leafCount = 0;
  float geometricError = 0.0f;
  uint8_t level = 0;
  Codec codec = Codec::Raw;
  uint8_t kind = 0;  // a ChunkKind, or a later kind this reader does not know

  bool operator==(const ChunkInfo&) const = default;
};

// The reason an attribute schema is invalid, or empty when it is valid.
std::string_view attributeSchemaProblem(const std::vector<AttributeDesc>& attributes);

// The first rule of specs/iso-format.md ("Header") that a frame breaks: the field (0 to 2: that
// component of the origin, 3: the size) and the reason; nullopt when the frame is valid.
struct FrameProblem {
  int field;
  std::string_view reason;
};
std::optional<FrameProblem> frameProblem(const Frame& frame);

// Whether key names a cell at level (key < 2^(3·level), level <= kMaxLevel).
constexpr bool isValidKey(uint8_t level, uint64_t key) {
  return level <= kMaxLevel && (key >> (3 * level)) == 0;
}

// Whether the cell (level, key) contains the cell (childLevel, childKey).
constexpr bool cellContains(uint8_t level, uint64_t key, uint8_t childLevel, uint64_t childKey) {
  return level <= childLevel && (childKey >> (3 * (childLevel - level))) == key;
}

// Bytes per corner that one attribute occupies with its encoding.
uint32_t encodedSize(const AttributeDesc& attribute);

std::string_view semanticName(Semantic semantic);
std::string_view encodingName(Encoding encoding);
std::string_view codecName(Codec codec);
std::string_view chunkKindName(uint8_t kind);  // "unknown" for kinds this version does not know

}  // namespace iso
