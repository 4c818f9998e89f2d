// Surface chunk payloads (specs/iso-format.md, "Surface chunks"): topology, corner numbering,
// quantization of corner attributes, and validation of untrusted payloads.
#include "iso/surface.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>

#include "bytes.h"
#include "iso/check.h"
#include "iso/error.h"
#include "iso/flat_map.h"
#include "iso/quantize.h"
#include "iso/reader.h"

namespace iso {

using detail::loadLE;
using detail::storeLE;

namespace {

// A rule of the format a topology breaks (layoutSurface's checks, caught by its two entries).
struct BrokenRule {
  std::string reason;
};

[[noreturn]] void invalid(const std::string& reason) {
  throw BrokenRule{"surface chunk: " + reason};
}

void checkRoots(const SurfaceTopology& t, uint8_t chunkLevel, uint64_t chunkKey, uint8_t maxLevel) {
  if (t.depth < 1) invalid("depth is 0");
  if (t.startLevel < chunkLevel) invalid("start level is above the chunk's cell");
  if (int(t.startLevel) + t.depth - 1 > maxLevel)
    invalid("levels go below the file's maximum level");
  if (t.rootKeys.empty()) invalid("no roots");
  for (size_t i = 0; i < t.rootKeys.size(); ++i) {
    const uint64_t key = t.rootKeys[i];
    if (!isValidKey(t.startLevel, key) || !cellContains(chunkLevel, chunkKey, t.startLevel, key))
      invalid("root " + std::to_string(i) + " is not inside the chunk's cell");
    if (i > 0 && key <= t.rootKeys[i - 1]) invalid("root keys are not strictly increasing");
  }
}

// The nodes in breadth-first order with keys, levels and first-child links.
std::vector<SurfaceNode> expandNodes(const SurfaceTopology& t) {
  std::vector<SurfaceNode> nodes;
  nodes.reserve(t.childMasks.size());
  for (uint64_t key : t.rootKeys) nodes.push_back({key, t.startLevel, 0, kNoNode, {}});
  size_t levelBegin = 0;
  for (int d = 0; d < t.depth; ++d) {
    const size_t levelEnd = nodes.size();
    if (levelEnd > t.childMasks.size()) invalid("fewer node masks than nodes");
    for (size_t i = levelBegin; i < levelEnd; ++i) {
      nodes[i].childMask = t.childMasks[i];
      if (d + 1 == t.depth || nodes[i].childMask == 0) continue;
      nodes[i].firstChild = static_cast<uint32_t>(nodes.size());
      for (int o = 0; o < 8; ++o)
        if (nodes[i].childMask & (1u << o))
          nodes.push_back(
              {nodes[i].key << 3 | uint64_t(o), uint8_t(nodes[i].level + 1), 0, kNoNode, {}});
      if (nodes.size() > t.childMasks.size()) invalid("fewer node masks than nodes");
    }
    levelBegin = levelEnd;
  }
  if (nodes.size() != t.childMasks.size()) invalid("more node masks than nodes");
  return nodes;
}

// Corners numbered in the order nodes first use them, found through an open-addressed table of
// 4-byte numbers (0: empty, else number + 1) that compares the corners' own points: a chunk's
// table stays in cache where one of (key, number) pairs would not.
class CornerNumbers {
 public:
  // Leaf corners are one per point, at the coarsest level that uses them; LOD corners (byLevel)
  // one per point and level.
  CornerNumbers(std::vector<CornerKey>& corners, size_t expected, bool byLevel)
      : corners_(corners),
        slots_(tableCapacity(expected), 0),
        mask_(slots_.size() - 1),
        byLevel_(byLevel) {}

  uint32_t number(const GridPoint& point, uint8_t level) {
    if ((corners_.size() + 1) * 2 > slots_.size()) grow();
    size_t i = slotOf(point, level);
    for (; slots_[i] != 0; i = (i + 1) & mask_) {
      CornerKey& corner = corners_[slots_[i] - 1];
      if (corner.point == point && (!byLevel_ || corner.level == level)) {
        corner.level = std::min(corner.level, level);
        return slots_[i] - 1;
      }
    }
    corners_.push_back({point, level});
    slots_[i] = uint32_t(corners_.size());
    return slots_[i] - 1;
  }

 private:
  size_t slotOf(const GridPoint& p, uint8_t level) const {
    const uint64_t l = byLevel_ ? level : 0;
    return hashBits(uint64_t(p.x) ^ uint64_t(p.y) << 22 ^ uint64_t(p.z) << 44 ^ l << 58) & mask_;
  }
  void grow() {
    slots_.assign(slots_.size() * 2, 0);
    mask_ = slots_.size() - 1;
    for (uint32_t n = 0; n < corners_.size(); ++n) {
      size_t i = slotOf(corners_[n].point, corners_[n].level);
      while (slots_[i] != 0) i = (i + 1) & mask_;
      slots_[i] = n + 1;
    }
  }

  std::vector<CornerKey>& corners_;
  std::vector<uint32_t> slots_;
  size_t mask_;
  bool byLevel_;
};

// Byte sizes of the payload's parts.
struct PayloadLayout {
  size_t rootsOffset = kSurfaceHeaderSize, masksOffset = 0, attributesOffset = 0, size = 0;
};

size_t pad4(size_t n) { return (n + 3) & ~size_t{3}; }

PayloadLayout payloadLayout(size_t roots, size_t nodes, size_t leafCorners, size_t lodCorners,
                            const std::vector<AttributeDesc>& schema) {
  PayloadLayout p;
  p.masksOffset = p.rootsOffset + 8 * roots;
  p.attributesOffset = pad4(p.masksOffset + nodes);
  p.size = p.attributesOffset;
  for (const AttributeDesc& a : schema)
    p.size += pad4(encodedSize(a) * leafCorners) + pad4(encodedSize(a) * lodCorners);
  return p;
}

float distanceUnit(uint8_t level, const AttributeDesc& a) {
  return static_cast<float>(nodeDiagonal(level) * double(a.scale));
}

void encodeValue(const AttributeDesc& a, const CornerValues& v, const CornerKey& key, size_t i,
                 std::byte* out) {
  switch (a.semantic) {
    case Semantic::SignedDistance: {
      const float f = v.distance[i];
      // A negative distance never rounds to 0: the surface is the boundary of {f < 0}, and 0
      // counts as outside, so that would move the surface across the corner.
      if (a.encoding == Encoding::Snorm8) {
        const float x = f / distanceUnit(key.level, a);
        const int8_t q = encodeSnorm8(x);
        storeLE<int8_t>(out, q == 0 && x < 0.0f ? int8_t(-1) : q);
      }
      if (a.encoding == Encoding::Snorm16) {
        const float x = f / distanceUnit(key.level, a);
        const int16_t q = encodeSnorm16(x);
        storeLE<int16_t>(out, q == 0 && x < 0.0f ? int16_t(-1) : q);
      }
      if (a.encoding == Encoding::Float32) storeLE<float>(out, f);
      return;
    }
    case Semantic::Normal: {
      const std::array<float, 3>& n = v.normal[i];
      if (a.encoding == Encoding::Float32) {
        for (int c = 0; c < 3; ++c) storeLE<float>(out + 4 * c, n[c]);
      } else if (a.encoding == Encoding::Oct16) {
        const auto q = encodeOctahedral(n, 8);
        storeLE<int8_t>(out, int8_t(q[0]));
        storeLE<int8_t>(out + 1, int8_t(q[1]));
      } else {
        const auto q = encodeOctahedral(n, 12);
        const uint32_t packed = (uint32_t(q[0]) & 0xFFF) | (uint32_t(q[1]) & 0xFFF) << 12;
        for (int b = 0; b < 3; ++b) out[b] = std::byte((packed >> (8 * b)) & 0xFF);
      }
      return;
    }
    case Semantic::Color:
      for (int c = 0; c < 3; ++c) {
        if (a.encoding == Encoding::Srgb8)
          storeLE<uint8_t>(out + c, linearToSrgb8(v.color[i][c]));
        else
          storeLE<float>(out + 4 * c, v.color[i][c]);
      }
      return;
    case Semantic::Occlusion: {
      const float o = std::clamp(v.occlusion[i], 0.0f, 1.0f);
      if (a.encoding == Encoding::Unorm8)
        storeLE<uint8_t>(out, uint8_t(std::lround(o * 255.0f)));
      else
        storeLE<float>(out, v.occlusion[i]);
      return;
    }
  }
}

int32_t signExtend12(uint32_t v) { return int32_t(v << 20) >> 20; }

void decodeValue(const AttributeDesc& a, const std::byte* in, const CornerKey& key, size_t i,
                 CornerValues& v) {
  switch (a.semantic) {
    case Semantic::SignedDistance:
      if (a.encoding == Encoding::Snorm8)
        v.distance[i] = decodeSnorm8(loadLE<int8_t>(in)) * distanceUnit(key.level, a);
      if (a.encoding == Encoding::Snorm16)
        v.distance[i] = decodeSnorm16(loadLE<int16_t>(in)) * distanceUnit(key.level, a);
      if (a.encoding == Encoding::Float32) v.distance[i] = loadLE<float>(in);
      return;
    case Semantic::Normal:
      if (a.encoding == Encoding::Float32) {
        for (int c = 0; c < 3; ++c) v.normal[i][c] = loadLE<float>(in + 4 * c);
      } else if (a.encoding == Encoding::Oct16) {
        v.normal[i] = decodeOctahedral({loadLE<int8_t>(in), loadLE<int8_t>(in + 1)}, 8);
      } else {
        const uint32_t packed = uint32_t(in[0]) | uint32_t(in[1]) << 8 | uint32_t(in[2]) << 16;
        v.normal[i] =
            decodeOctahedral({signExtend12(packed & 0xFFF), signExtend12(packed >> 12)}, 12);
      }
      return;
    case Semantic::Color:
      for (int c = 0; c < 3; ++c)
        v.color[i][c] = a.encoding == Encoding::Srgb8 ? srgb8ToLinear(loadLE<uint8_t>(in + c))
                                                      : loadLE<float>(in + 4 * c);
      return;
    case Semantic::Occlusion:
      v.occlusion[i] =
          a.encoding == Encoding::Unorm8 ? float(loadLE<uint8_t>(in)) / 255.0f : loadLE<float>(in);
      return;
  }
}

void resizeValues(CornerValues& v, const std::vector<AttributeDesc>& schema, size_t n) {
  v.distance.assign(n, 0.0f);
  for (const AttributeDesc& a : schema) {
    if (a.semantic == Semantic::Normal) v.normal.assign(n, {0.0f, 0.0f, 1.0f});
    if (a.semantic == Semantic::Color) v.color.assign(n, {0.0f, 0.0f, 0.0f});
    if (a.semantic == Semantic::Occlusion) v.occlusion.assign(n, 1.0f);
  }
}

void checkValueCounts(const CornerValues& v, const std::vector<AttributeDesc>& schema, size_t n) {
  const auto invalid = [](const std::string& reason) {
    throw InternalError("surface chunk: " + reason);
  };
  if (v.distance.size() != n) invalid("distance count differs from the corner count");
  for (const AttributeDesc& a : schema) {
    if (a.semantic == Semantic::Normal && v.normal.size() != n) invalid("normal count differs");
    if (a.semantic == Semantic::Color && v.color.size() != n) invalid("color count differs");
    if (a.semantic == Semantic::Occlusion && v.occlusion.size() != n)
      invalid("occlusion count differs");
  }
}

}  // namespace

std::array<double, 8> trilinearWeights(const std::array<double, 3>& u) {
  std::array<double, 8> w{};
  for (int c = 0; c < 8; ++c) {
    double weight = 1.0;
    for (int a = 0; a < 3; ++a) weight *= ((c >> a) & 1) ? u[size_t(a)] : 1.0 - u[size_t(a)];
    w[size_t(c)] = weight;
  }
  return w;
}

std::array<std::array<double, 8>, 3> trilinearWeightGradients(const std::array<double, 3>& u) {
  std::array<std::array<double, 8>, 3> g{};
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 8; ++c) {
      double d = ((c >> a) & 1) ? 1.0 : -1.0;
      for (int b = 0; b < 3; ++b)
        if (b != a) d *= ((c >> b) & 1) ? u[size_t(b)] : 1.0 - u[size_t(b)];
      g[size_t(a)][size_t(c)] = d;
    }
  return g;
}

namespace {

// Corner c of the cell at `cell` (a level's coordinates), on the finest grid (shift: kMaxLevel
// minus the level).
GridPoint cellCorner(const std::array<uint32_t, 3>& cell, int shift, int c) {
  return {(cell[0] + uint32_t(c & 1)) << shift, (cell[1] + uint32_t((c >> 1) & 1)) << shift,
          (cell[2] + uint32_t((c >> 2) & 1)) << shift};
}

}  // namespace

GridPoint cornerPoint(uint8_t level, uint64_t key, int corner) {
  return cellCorner(mortonDecode(key), kMaxLevel - level, corner);
}

namespace {

CornerLayout layoutOf(const SurfaceTopology& topology, uint8_t chunkLevel, uint64_t chunkKey,
                      uint8_t maxLevel) {
  checkRoots(topology, chunkLevel, chunkKey, maxLevel);
  CornerLayout layout;
  layout.nodes = expandNodes(topology);
  // About 1.8 leaf corners and 0.6 LOD corners a node in scans; the tables grow when needed.
  CornerNumbers leaf(layout.leafCorners, layout.nodes.size() * 2, false);
  CornerNumbers lod(layout.lodCorners, layout.nodes.size(), true);
  for (SurfaceNode& node : layout.nodes) {
    const auto cell = mortonDecode(node.key);
    CornerNumbers& numbers = node.isLeaf() ? leaf : lod;
    for (int c = 0; c < kCorners; ++c)
      node.corners[size_t(c)] =
          numbers.number(cellCorner(cell, kMaxLevel - node.level, c), node.level);
  }
  return layout;
}

}  // namespace

std::optional<CornerLayout> tryLayoutSurface(const SurfaceTopology& topology, uint8_t chunkLevel,
                                             uint64_t chunkKey, uint8_t maxLevel,
                                             std::string& problem) {
  try {
    return layoutOf(topology, chunkLevel, chunkKey, maxLevel);
  } catch (const BrokenRule& broken) {
    problem = broken.reason;
    return std::nullopt;
  }
}

CornerLayout layoutSurface(const SurfaceTopology& topology, uint8_t chunkLevel, uint64_t chunkKey,
                           uint8_t maxLevel) {
  try {
    return layoutOf(topology, chunkLevel, chunkKey, maxLevel);
  } catch (const BrokenRule& broken) {
    throw InternalError(broken.reason);
  }
}

std::vector<std::byte> encodeSurfaceChunk(const SurfaceTopology& topology,
                                          const CornerLayout& layout,
                                          const std::vector<AttributeDesc>& schema,
                                          const CornerValues& leafValues,
                                          const CornerValues& lodValues) {
  checkValueCounts(leafValues, schema, layout.leafCorners.size());
  checkValueCounts(lodValues, schema, layout.lodCorners.size());
  const PayloadLayout p =
      payloadLayout(topology.rootKeys.size(), topology.childMasks.size(), layout.leafCorners.size(),
                    layout.lodCorners.size(), schema);
  std::vector<std::byte> out(p.size);
  std::byte* b = out.data();
  storeLE<uint32_t>(b + 0, uint32_t(topology.rootKeys.size()));
  storeLE<uint32_t>(b + 4, uint32_t(topology.childMasks.size()));
  storeLE<uint32_t>(b + 8, uint32_t(layout.leafCorners.size()));
  storeLE<uint32_t>(b + 12, uint32_t(layout.lodCorners.size()));
  storeLE<uint8_t>(b + 16, topology.startLevel);
  storeLE<uint8_t>(b + 17, topology.depth);
  for (size_t i = 0; i < topology.rootKeys.size(); ++i)
    storeLE<uint64_t>(b + p.rootsOffset + 8 * i, topology.rootKeys[i]);
  std::memcpy(b + p.masksOffset, topology.childMasks.data(), topology.childMasks.size());
  size_t at = p.attributesOffset;
  for (const AttributeDesc& a : schema) {
    const size_t size = encodedSize(a);
    for (const auto* part : {&leafValues, &lodValues}) {
      const std::vector<CornerKey>& keys =
          part == &leafValues ? layout.leafCorners : layout.lodCorners;
      for (size_t i = 0; i < keys.size(); ++i) encodeValue(a, *part, keys[i], i, b + at + size * i);
      at += pad4(size * keys.size());
    }
  }
  return out;
}

float roundTripDistance(float f, uint8_t level, const AttributeDesc& distance) {
  CornerValues v;
  v.distance = {f};
  const CornerKey key{{}, level};
  std::array<std::byte, 16> bytes{};
  encodeValue(distance, v, key, 0, bytes.data());
  decodeValue(distance, bytes.data(), key, 0, v);
  return v.distance[0];
}

namespace {

[[noreturn]] void failChunk(const Reader& reader, uint32_t id, const std::string& reason) {
  throw FileError(reader.name(), reader.chunk(id).offset,
                  "chunk " + std::to_string(id) + ": " + reason);
}

bool allFinite(const CornerValues& v) {
  const auto finite = [](float x) { return std::isfinite(x); };
  if (!std::all_of(v.distance.begin(), v.distance.end(), finite)) return false;
  for (const auto* vectors : {&v.normal, &v.color})
    for (const auto& x : *vectors)
      if (!std::all_of(x.begin(), x.end(), finite)) return false;
  return std::all_of(v.occlusion.begin(), v.occlusion.end(), finite);
}

}  // namespace

SurfaceChunk decodeSurfaceChunk(const Reader& reader, uint32_t id) {
  const ChunkInfo& chunk = reader.chunk(id);
  const auto fail = [&](const std::string& reason) { failChunk(reader, id, reason); };
  if (chunk.kind != kSurfaceKind) fail("not a surface chunk");
  const ChunkData data = reader.payload(id);  // checked; the mapped bytes when stored raw
  const std::span<const std::byte> payload = data.bytes();
  if (payload.size() < kSurfaceHeaderSize) fail("surface payload is shorter than its header");
  const std::byte* b = payload.data();
  const uint32_t rootCount = loadLE<uint32_t>(b), nodeCount = loadLE<uint32_t>(b + 4);
  const uint32_t leafCount = loadLE<uint32_t>(b + 8), lodCount = loadLE<uint32_t>(b + 12);
  if (loadLE<uint16_t>(b + 18) != 0 || loadLE<uint32_t>(b + 20) != 0)
    fail("reserved surface header bytes are not zero");
  const std::vector<AttributeDesc>& schema = reader.header().attributes;
  // Every count is bounded by the payload size before anything is allocated from it.
  const uint64_t minimum = kSurfaceHeaderSize + 8ull * rootCount + nodeCount;
  if (rootCount > nodeCount || minimum > payload.size() || leafCount > 8ull * nodeCount ||
      lodCount > 8ull * nodeCount)
    fail("surface header counts do not fit the payload");
  const PayloadLayout p = payloadLayout(rootCount, nodeCount, leafCount, lodCount, schema);
  if (p.size != payload.size())
    fail("surface payload is " + std::to_string(payload.size()) + " bytes, its header implies " +
         std::to_string(p.size));

  SurfaceChunk out;
  out.topology.startLevel = loadLE<uint8_t>(b + 16);
  out.topology.depth = loadLE<uint8_t>(b + 17);
  out.topology.rootKeys.resize(rootCount);
  for (uint32_t i = 0; i < rootCount; ++i)
    out.topology.rootKeys[i] = loadLE<uint64_t>(b + p.rootsOffset + 8ull * i);
  out.topology.childMasks.resize(nodeCount);
  std::memcpy(out.topology.childMasks.data(), b + p.masksOffset, nodeCount);
  std::string problem;
  std::optional<CornerLayout> layout =
      tryLayoutSurface(out.topology, chunk.level, chunk.key, reader.header().maxLevel, problem);
  if (!layout) fail(problem);
  out.layout = std::move(*layout);
  if (out.layout.leafCorners.size() != leafCount || out.layout.lodCorners.size() != lodCount)
    fail("corner counts differ from those the nodes use");
  const size_t leaves = size_t(std::count_if(out.layout.nodes.begin(), out.layout.nodes.end(),
                                             [](const SurfaceNode& n) { return n.isLeaf(); }));
  if (nodeCount != chunk.nodeCount || leaves != chunk.leafCount)
    fail("the chunk table gives " + std::to_string(chunk.nodeCount) + " nodes and " +
         std::to_string(chunk.leafCount) + " filled leaves, the data " + std::to_string(nodeCount) +
         " and " + std::to_string(leaves));
  resizeValues(out.leafValues, schema, leafCount);
  resizeValues(out.lodValues, schema, lodCount);
  size_t at = p.attributesOffset;
  for (const AttributeDesc& a : schema) {
    const size_t size = encodedSize(a);
    for (CornerValues* part : {&out.leafValues, &out.lodValues}) {
      const std::vector<CornerKey>& keys =
          part == &out.leafValues ? out.layout.leafCorners : out.layout.lodCorners;
      for (size_t i = 0; i < keys.size(); ++i) decodeValue(a, b + at + size * i, keys[i], i, *part);
      at += pad4(size * keys.size());
    }
  }
  if (!allFinite(out.leafValues) || !allFinite(out.lodValues)) fail("a corner value is not finite");
  return out;
}

}  // namespace iso
