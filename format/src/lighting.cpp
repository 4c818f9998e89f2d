// Lighting chunks (iso/lighting.h; specs/iso-format.md, "Lighting chunks").
#include "iso/lighting.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "bytes.h"
#include "iso/check.h"
#include "iso/error.h"
#include "iso/flat_map.h"
#include "iso/reader.h"
#include "iso/surface.h"

namespace iso {
namespace {

using detail::loadLE;
using detail::storeLE;

constexpr int kMantissaBits = 9, kExponentBias = 15, kMaxExponent = 31;

[[noreturn]] void fail(const Reader& reader, uint32_t id, const std::string& reason) {
  throw FileError(reader.name(), reader.chunk(id).offset,
                  "chunk " + std::to_string(id) + ": " + reason);
}

}  // namespace

uint32_t encodeRgb9e5(const std::array<float, 3>& rgb) {
  std::array<float, 3> c{};
  for (size_t i = 0; i < 3; ++i) c[i] = rgb[i] > 0.0f ? std::min(rgb[i], kMaxRgb9e5) : 0.0f;
  const float largest = std::max({c[0], c[1], c[2]});
  if (!(largest > 0.0f)) return 0;
  // The exponent of the largest channel, so that its mantissa is 256 to 511 (or 512: one more).
  int exponent = std::max(-kExponentBias - 1, int(std::floor(std::log2(largest)))) + 1 +
                 kExponentBias;
  double unit = std::ldexp(1.0, exponent - kExponentBias - kMantissaBits);
  if (std::floor(double(largest) / unit + 0.5) >= double(1 << kMantissaBits)) {
    unit *= 2.0;
    exponent += 1;
  }
  exponent = std::clamp(exponent, 0, kMaxExponent);
  uint32_t code = uint32_t(exponent) << 27;
  for (size_t i = 0; i < 3; ++i) {
    const double m = std::min(std::floor(double(c[i]) / unit + 0.5), 511.0);
    code |= uint32_t(m) << (kMantissaBits * i);
  }
  return code;
}

std::array<float, 3> decodeRgb9e5(uint32_t code) {
  const double unit = std::ldexp(1.0, int(code >> 27) - kExponentBias - kMantissaBits);
  return {float(double(code & 511u) * unit), float(double(code >> 9 & 511u) * unit),
          float(double(code >> 18 & 511u) * unit)};
}

std::vector<std::byte> encodeLightingChunk(const ChunkLighting& lighting) {
  const size_t count = lighting.leaf.size() + lighting.lod.size();
  std::vector<std::byte> data(kLightingHeaderSize + 4 * count + 8 * lighting.overrides.size());
  storeLE<uint32_t>(data.data(), lighting.surfaceChunk);
  storeLE<uint32_t>(data.data() + 4, uint32_t(lighting.leaf.size()));
  storeLE<uint32_t>(data.data() + 8, uint32_t(lighting.lod.size()));
  storeLE<uint32_t>(data.data() + 12, uint32_t(lighting.overrides.size()));
  size_t at = kLightingHeaderSize;
  for (const auto* values : {&lighting.leaf, &lighting.lod})
    for (const std::array<float, 3>& rgb : *values) {
      storeLE<uint32_t>(data.data() + at, encodeRgb9e5(rgb));
      at += 4;
    }
  for (const CornerOverride& o : lighting.overrides) {
    ISO_CHECK(o.node < (1u << 29) && o.corner < 8);
    storeLE<uint32_t>(data.data() + at, o.node << 3 | o.corner);
    storeLE<uint32_t>(data.data() + at + 4, encodeRgb9e5(o.value));
    at += 8;
  }
  return data;
}

namespace {

// The header of lighting chunk `id`: its surface chunk and corner counts, checked against the
// chunk table.
struct LightingHeader {
  uint32_t surfaceChunk, leafCorners, lodCorners, overrides;
};

LightingHeader lightingHeader(const Reader& reader, uint32_t id, std::span<const std::byte> data) {
  if (reader.chunk(id).kind != kLightingKind) fail(reader, id, "not a lighting chunk");
  if (data.size() < kLightingHeaderSize) fail(reader, id, "lighting data is shorter than its header");
  const LightingHeader h{loadLE<uint32_t>(data.data()), loadLE<uint32_t>(data.data() + 4),
                         loadLE<uint32_t>(data.data() + 8), loadLE<uint32_t>(data.data() + 12)};
  if (h.surfaceChunk >= reader.chunks().size() ||
      reader.chunk(h.surfaceChunk).kind != kSurfaceKind)
    fail(reader, id,
         "lighting of chunk " + std::to_string(h.surfaceChunk) + ", which is not a surface chunk");
  const ChunkInfo &self = reader.chunk(id), &surface = reader.chunk(h.surfaceChunk);
  if (self.level != surface.level || self.key != surface.key)
    fail(reader, id, "the lighting chunk's cell is not its surface chunk's");
  if (data.size() != kLightingHeaderSize + 4 * (uint64_t{h.leafCorners} + h.lodCorners) +
                         8 * uint64_t{h.overrides})
    fail(reader, id, "lighting data is not its header, 4 bytes a corner and 8 an override");
  return h;
}

}  // namespace

ChunkLighting decodeLightingChunk(const Reader& reader, uint32_t id) {
  const ChunkData payload = reader.payload(id);
  const std::span<const std::byte> data = payload.bytes();
  const LightingHeader h = lightingHeader(reader, id, data);
  ChunkLighting out;
  out.surfaceChunk = h.surfaceChunk;
  out.leaf.resize(h.leafCorners);
  out.lod.resize(h.lodCorners);
  size_t at = kLightingHeaderSize;
  for (auto* values : {&out.leaf, &out.lod})
    for (std::array<float, 3>& rgb : *values) {
      rgb = decodeRgb9e5(loadLE<uint32_t>(data.data() + at));
      at += 4;
    }
  out.overrides.resize(h.overrides);
  uint64_t previous = 0;
  for (uint32_t i = 0; i < h.overrides; ++i) {
    const uint32_t place = loadLE<uint32_t>(data.data() + at);
    if (i > 0 && place <= previous)
      fail(reader, id, "the lighting overrides are not in increasing node and corner order");
    previous = place;
    out.overrides[i] = {place >> 3, uint8_t(place & 7),
                        decodeRgb9e5(loadLE<uint32_t>(data.data() + at + 4))};
    at += 8;
  }
  return out;
}

std::vector<uint32_t> lightingChunks(const Reader& reader) {
  std::vector<uint32_t> of(reader.chunks().size(), kNoParent);
  for (const ChunkInfo& c : reader.chunks()) {
    if (c.kind != kLightingKind) continue;
    // The header alone: the first 16 bytes of the decoded payload.
    std::vector<std::byte> data(c.rawSize);
    reader.decodePayload(c.id, data);
    const LightingHeader h = lightingHeader(reader, c.id, data);
    if (of[h.surfaceChunk] != kNoParent)
      fail(reader, c.id,
           "surface chunk " + std::to_string(h.surfaceChunk) + " has a second lighting chunk");
    of[h.surfaceChunk] = c.id;
  }
  return of;
}

std::vector<uint32_t> lightingByCell(const Reader& reader) {
  const auto cell = [](const ChunkInfo& c) { return (uint64_t{1} << (3 * c.level)) | c.key; };
  FlatMap<uint64_t, uint32_t> cells(64);
  for (const ChunkInfo& c : reader.chunks())
    if (c.kind == kLightingKind && !cells.insert(cell(c), c.id).second)
      return lightingChunks(reader);
  std::vector<uint32_t> of(reader.chunks().size(), kNoParent);
  for (const ChunkInfo& c : reader.chunks())
    if (c.kind == kSurfaceKind)
      if (const uint32_t* id = cells.find(cell(c))) of[c.id] = *id;
  return of;
}

void attachLighting(const Reader& reader, uint32_t id, uint32_t surfaceId, SurfaceChunk& chunk) {
  ChunkLighting lighting = decodeLightingChunk(reader, id);
  if (lighting.surfaceChunk != surfaceId)
    fail(reader, id,
         "lights surface chunk " + std::to_string(lighting.surfaceChunk) + ", not chunk " +
             std::to_string(surfaceId) + " whose cell it shares");
  if (lighting.leaf.size() != chunk.layout.leafCorners.size() ||
      lighting.lod.size() != chunk.layout.lodCorners.size())
    fail(reader, id,
         "lighting of " + std::to_string(lighting.leaf.size()) + " leaf and " +
             std::to_string(lighting.lod.size()) + " level-of-detail corners; its surface chunk " +
             std::to_string(lighting.surfaceChunk) + " has " +
             std::to_string(chunk.layout.leafCorners.size()) + " and " +
             std::to_string(chunk.layout.lodCorners.size()));
  for (const CornerOverride& o : lighting.overrides)
    if (o.node >= chunk.layout.nodes.size() || !chunk.layout.nodes[o.node].isLeaf())
      fail(reader, id,
           "a lighting override of node " + std::to_string(o.node) +
               ", which is not a filled leaf of surface chunk " +
               std::to_string(lighting.surfaceChunk));
  chunk.leafValues.irradiance = std::move(lighting.leaf);
  chunk.lodValues.irradiance = std::move(lighting.lod);
  chunk.irradianceOverrides = std::move(lighting.overrides);
}

}  // namespace iso
