// Building the GPU form of surface chunks (specs/viewer.md, "Chunks on the GPU").
#include "tracer/blob.h"

#include "iso/lighting.h"
#include "iso/reader.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <glm/glm.hpp>
#include <glm/packing.hpp>
#include <stdexcept>

#include "iso/check.h"
#include "iso/quantize.h"
#include "shaders/shared.h"

namespace iso::viewer {
namespace {

// A leaf's corners whose irradiance is its own (bit c of mask: corner c's code).
struct OwnCorners {
  std::array<uint32_t, 8> code{};
  uint32_t mask = 0;
};

using gpu::kBlobData;
using gpu::kBlobHeaderWords;
using gpu::kBlobNodeCount;
using gpu::kBlobNodes;
using gpu::kBlobWords;
using gpu::kNodeCut;
using gpu::kNodeErrorShift;

// The distances of a record (shared.h): the file's snorm8 codes, found again from the decoded
// values (value / unit rounds back to the code exactly), with each corner's scale as a shift
// from the node's level; or float32 in cell units. Either way the tracer's values are the decoded
// ones times a power of two, which is exact.
void appendDistances(std::vector<uint32_t>& out, const SurfaceNode& node,
                     const CornerValues& values, std::span<const CornerKey> keys,
                     const BlobOptions& options) {
  if (options.floatDistances) {
    const float perCell = std::ldexp(1.0f, int(node.level));
    for (int c = 0; c < 8; ++c)
      out.push_back(std::bit_cast<uint32_t>(values.distance.at(node.corners[c]) * perCell));
    return;
  }
  uint32_t codes[2] = {0, 0}, shifts = 0;
  for (int c = 0; c < 8; ++c) {
    const CornerKey& key = keys[node.corners[c]];
    const int8_t code = encodeSnorm8(values.distance.at(node.corners[c]) /
                                     (options.distanceUnit * std::ldexp(1.0f, -int(key.level))));
    // The corner's scale is its coarsest leaf's, at or above the node's level; a shift beyond 15
    // (leaves 16 levels apart at one corner, which a 2:1-balanced file never has) is clamped.
    const int shift = std::clamp(int(node.level) - int(key.level), 0, 15);
    codes[c / 4] |= uint32_t(uint8_t(code)) << (8 * (c % 4));
    shifts |= uint32_t(shift) << (4 * c);
  }
  out.push_back(codes[0]);
  out.push_back(codes[1]);
  out.push_back(shifts);
}

// The normal and color words of each corner of a chunk's values, encoded once (a corner is shared
// by up to 8 nodes): the octahedral snorm8 pair of its normal (the file's own 8-bit encoding), and
// its sRGB RGB8 color with the occlusion as unorm8 alpha (shared.h).
struct CornerWords {
  std::vector<uint16_t> normals;
  std::vector<uint32_t> colors;
  std::vector<uint32_t> irradiance;  // RGB9E5
};

CornerWords encodeCorners(const CornerValues& values, const BlobOptions& options) {
  CornerWords words;
  if (options.normals) {
    words.normals.resize(values.size());
    for (size_t i = 0; i < values.size(); ++i) {
      const auto q = encodeOctahedral(values.normal.at(i), 8);
      words.normals[i] = uint16_t(uint8_t(q[0]) | uint8_t(q[1]) << 8);
    }
  }
  if (options.colors || options.occlusion) {
    words.colors.resize(values.size());
    for (size_t i = 0; i < values.size(); ++i) {
      uint32_t word = 0x00FFFFFFu;
      if (options.colors) {
        const auto& rgb = values.color.at(i);
        word = uint32_t(linearToSrgb8(rgb[0])) | uint32_t(linearToSrgb8(rgb[1])) << 8 |
               uint32_t(linearToSrgb8(rgb[2])) << 16;
      }
      const float open = options.occlusion ? values.occlusion.at(i) : 1.0f;
      words.colors[i] = word | uint32_t(std::lround(std::clamp(open, 0.0f, 1.0f) * 255.0f)) << 24;
    }
  }
  if (options.irradiance) {
    // The file's own codes (values.irradiance are their decoded values, or none: a surface chunk
    // without a lighting chunk receives nothing).
    words.irradiance.assign(values.size(), 0u);
    for (size_t i = 0; i < values.irradiance.size() && i < values.size(); ++i)
      words.irradiance[i] = encodeRgb9e5(values.irradiance[i]);
  }
  return words;
}

// Append the corner record of a node: its 8 corners' values.
void appendRecord(std::vector<uint32_t>& out, const SurfaceNode& node, const CornerValues& values,
                  const CornerWords& words, std::span<const CornerKey> keys,
                  const BlobOptions& options, const OwnCorners& own = {}) {
  appendDistances(out, node, values, keys, options);
  if (options.normals) {
    for (int c = 0; c < 8; c += 2)
      out.push_back(uint32_t(words.normals.at(node.corners[c])) |
                    uint32_t(words.normals.at(node.corners[c + 1])) << 16);
  }
  if (options.colors || options.occlusion) {
    for (int c = 0; c < 8; ++c) out.push_back(words.colors.at(node.corners[c]));
  }
  if (options.irradiance)
    for (int c = 0; c < 8; ++c)
      out.push_back((own.mask >> c & 1u) != 0 ? own.code[size_t(c)]
                                               : words.irradiance.at(node.corners[c]));
}

}  // namespace

ChunkTree::ChunkTree(std::span<const ChunkInfo> chunks) : chunks_(chunks) {
  children_.resize(chunks.size());
  for (const ChunkInfo& c : chunks) {
    if (c.kind != kSurfaceKind) continue;
    if (c.parent == kNoParent) {
      if (c.level == 0 && top_ == kNoParent) top_ = c.id;
    } else if (chunks[c.parent].kind == kSurfaceKind) {
      children_[c.parent].push_back(c.id);
    }
  }
}

uint32_t ChunkTree::childCovering(uint32_t parent, uint8_t level, uint64_t key) const {
  for (uint32_t child : children_.at(parent)) {
    const ChunkInfo& c = chunks_[child];
    if (cellContains(c.level, c.key, level, key)) return child;
  }
  return kNoParent;
}

BlobOptions blobOptionsOf(const Reader& reader) {
  const FileHeader& header = reader.header();
  BlobOptions o;
  auto lighting = std::make_shared<std::vector<uint32_t>>(lightingByCell(reader));
  o.irradiance = std::any_of(lighting->begin(), lighting->end(),
                             [](uint32_t id) { return id != kNoParent; });
  if (o.irradiance) o.lightingOf = std::move(lighting);
  for (const AttributeDesc& d : header.attributes) {
    if (d.semantic == Semantic::Normal) o.normals = true;
    if (d.semantic == Semantic::Color) o.colors = true;
    if (d.semantic == Semantic::Occlusion) o.occlusion = true;
    if (d.semantic == Semantic::SignedDistance) {
      o.floatDistances = d.encoding != Encoding::Snorm8;
      o.distanceUnit = float(nodeDiagonal(0) * double(d.scale));  // the format's unit at level 0
    }
  }
  return o;
}

uint32_t recordOptionBits(const BlobOptions& o) {
  return (o.normals ? gpu::kOptionNormals : 0u) | (o.colors ? gpu::kOptionColors : 0u) |
         (o.occlusion ? gpu::kOptionOcclusion : 0u) |
         (o.floatDistances ? gpu::kOptionFloatDistances : 0u) |
         (o.irradiance ? gpu::kOptionIrradiance : 0u);
}

uint32_t recordWords(const BlobOptions& options) {
  return (options.floatDistances ? gpu::kRecordFloatDistanceWords : gpu::kRecordDistanceWords) +
         (options.normals ? gpu::kRecordNormalWords : 0) +
         (options.colors || options.occlusion ? gpu::kRecordColorWords : 0) +
         (options.irradiance ? gpu::kRecordIrradianceWords : 0);
}

SurfaceChunk decodeBlobChunk(const Reader& reader, uint32_t id, const BlobOptions& options) {
  SurfaceChunk chunk = decodeSurfaceChunk(reader, id);
  if (options.irradiance && options.lightingOf && (*options.lightingOf)[id] != kNoParent)
    attachLighting(reader, (*options.lightingOf)[id], id, chunk);
  return chunk;
}

void setColorTable(gpu::FrameParams& params) {
  // Bound k: the least float whose code is above k, by bisection on the bits of the floats in
  // [0, 1] (ordered as their bits are); the encoder is monotonic.
  static const std::array<float, 256> bounds = [] {
    std::array<float, 256> b{};
    for (uint32_t k = 0; k < 255; ++k) {
      uint32_t lo = 0, hi = std::bit_cast<uint32_t>(1.0f);  // code(lo) <= k < code(hi)
      while (hi - lo > 1) {
        const uint32_t mid = lo + (hi - lo) / 2;
        (linearToSrgb8(std::bit_cast<float>(mid)) > k ? hi : lo) = mid;
      }
      b[k] = std::bit_cast<float>(hi);
    }
    b[255] = 2.0f;
    return b;
  }();
  for (uint32_t i = 0; i < 256; ++i) {
    params.srgbToLinear[i / 4][i % 4] = srgb8ToLinear(uint8_t(i));
    params.srgbBounds[i / 4][i % 4] = bounds[i];
  }
}

namespace {

// The node's trilinear interpolation at local coordinates u in [0, 1]^3 (corner c = x + 2y + 4z).
float trilinear(const std::array<float, 8>& f, float x, float y, float z) {
  const float a = f[0] + (f[1] - f[0]) * x, b = f[2] + (f[3] - f[2]) * x;
  const float c = f[4] + (f[5] - f[4]) * x, d = f[6] + (f[7] - f[6]) * x;
  const float e = a + (b - a) * y, g = c + (d - c) * y;
  return e + (g - e) * z;
}

std::array<float, 8> distancesOf(const SurfaceNode& node, const CornerValues& values) {
  std::array<float, 8> f{};
  for (int c = 0; c < 8; ++c) f[c] = values.distance.at(node.corners[c]);
  return f;
}

}  // namespace

uint32_t encodeNodeError(double error, uint8_t level) {
  if (!(error > 0.0)) return 0;
  const double relative = std::ldexp(error, int(level));  // in units of the node's edge
  const double code = std::ceil(8.0 * std::log2(relative)) + 128.0;
  return code >= 255.0 ? 255u : uint32_t(std::max(code, 1.0));
}

std::vector<float> nodeErrors(const SurfaceChunk& chunk, float chunkError, uint32_t lastLevel) {
  const std::vector<SurfaceNode>& nodes = chunk.layout.nodes;
  std::vector<float> error(nodes.size(), 0.0f);
  // Children follow their parents (topology order): bottom up from the last node.
  for (size_t i = nodes.size(); i-- > 0;) {
    const SurfaceNode& node = nodes[i];
    if (node.isLeaf()) continue;
    if (node.level == lastLevel) {  // a cut node: its children are in other chunks
      error[i] = chunkError;
      continue;
    }
    const std::array<float, 8> f = distancesOf(node, chunk.lodValues);
    float worst = 0.0f;
    uint32_t child = node.firstChild;
    for (int o = 0; o < 8; ++o) {
      if (!(node.childMask & (1u << o))) continue;
      const SurfaceNode& c = nodes[child];
      const std::array<float, 8> g =
          distancesOf(c, c.isLeaf() ? chunk.leafValues : chunk.lodValues);
      float deviation = 0.0f;
      for (int k = 0; k < 8; ++k) {
        const float x = 0.5f * float((o & 1) + (k & 1)),
                    y = 0.5f * float(((o >> 1) & 1) + ((k >> 1) & 1)),
                    z = 0.5f * float(((o >> 2) & 1) + ((k >> 2) & 1));
        deviation = std::max(deviation, std::abs(trilinear(f, x, y, z) - g[k]));
      }
      worst = std::max(worst, error[child] + deviation);
      ++child;
    }
    error[i] = worst;
  }
  return error;
}

std::vector<uint32_t> buildBlob(const SurfaceChunk& chunk, uint32_t id, const ChunkTree& tree,
                                const BlobOptions& options) {
  const std::vector<SurfaceNode>& nodes = chunk.layout.nodes;
  const uint8_t lastLevel = uint8_t(chunk.topology.startLevel + chunk.topology.depth - 1);
  // Records: one per node, in node order (a leaf's patch, or an internal node's coarser one).
  std::vector<uint32_t> records;
  records.reserve(nodes.size() * recordWords(options));
  const CornerWords leafWords = encodeCorners(chunk.leafValues, options);
  const CornerWords lodWords = encodeCorners(chunk.lodValues, options);
  size_t nextOwn = 0;  // the leaves' own corners, in node order
  for (uint32_t i = 0; i < nodes.size(); ++i) {
    const SurfaceNode& node = nodes[i];
    if (node.isLeaf()) {
      OwnCorners own;
      for (; options.irradiance && nextOwn < chunk.irradianceOverrides.size() &&
             chunk.irradianceOverrides[nextOwn].node == i;
           ++nextOwn) {
        const CornerOverride& o = chunk.irradianceOverrides[nextOwn];
        own.code[o.corner] = encodeRgb9e5(o.value);
        own.mask |= 1u << o.corner;
      }
      appendRecord(records, node, chunk.leafValues, leafWords, chunk.layout.leafCorners, options,
                   own);
    } else {
      appendRecord(records, node, chunk.lodValues, lodWords, chunk.layout.lodCorners, options);
    }
  }
  // Cut nodes: links to the roots of the child chunks. A child chunk's roots are the children of
  // this chunk's last-level nodes inside its cell, in key order, so counting them in node order
  // gives each one's root index there.
  std::vector<uint32_t> links;
  std::vector<uint32_t> linkOf(nodes.size(), kNoNode);
  std::vector<std::pair<uint32_t, uint32_t>> rootCounts;  // (child chunk, roots so far)
  for (size_t i = 0; i < nodes.size(); ++i) {
    const SurfaceNode& node = nodes[i];
    if (node.isLeaf() || node.level != lastLevel) continue;
    std::vector<uint32_t> nodeLinks;
    bool complete = true;
    for (int o = 0; o < 8 && complete; ++o) {
      if (!(node.childMask & (1u << o))) continue;
      const uint64_t childKey = node.key << 3 | uint64_t(o);
      const uint32_t child = tree.childCovering(id, uint8_t(node.level + 1), childKey);
      if (child == kNoParent) {
        complete = false;
        break;
      }
      auto it = std::find_if(rootCounts.begin(), rootCounts.end(),
                             [&](const auto& p) { return p.first == child; });
      if (it == rootCounts.end()) it = rootCounts.insert(rootCounts.end(), {child, 0});
      nodeLinks.push_back(child);
      nodeLinks.push_back(it->second++);
    }
    if (complete) {  // else (a file without the child chunk) the node is drawn as its patch
      linkOf[i] = uint32_t(links.size());
      links.insert(links.end(), nodeLinks.begin(), nodeLinks.end());
    }
  }
  const std::vector<float> errors = nodeErrors(chunk, tree.geometricError(id), lastLevel);
  const uint32_t nodeCount = uint32_t(nodes.size());
  const size_t nodesAt = kBlobHeaderWords, linksAt = nodesAt + 2 * size_t(nodeCount);
  const size_t dataAt = (linksAt + links.size() + 1) & ~size_t(1);  // records start on 8 bytes
  const size_t total = dataAt + records.size();
  if (total > (size_t(1) << 31))
    throw std::length_error("chunk " + std::to_string(id) + " is too large for the viewer");
  std::vector<uint32_t> blob(total, 0);
  blob[kBlobNodeCount] = nodeCount;
  blob[kBlobWords] = uint32_t(total);
  blob[kBlobNodes] = uint32_t(nodesAt);
  blob[kBlobData] = uint32_t(dataAt);
  for (size_t i = 0; i < nodes.size(); ++i) {
    const SurfaceNode& node = nodes[i];
    uint32_t w0 = node.childMask, w1 = 0;
    if (node.isLeaf()) {
      // A filled leaf: its record is the node's.
    } else if (node.level != lastLevel) {
      w1 = node.firstChild;
    } else if (linkOf[i] != kNoNode) {
      w0 |= kNodeCut;
      w1 = uint32_t(linksAt + linkOf[i]);
    } else {
      w0 = 0;  // children missing from the file: a leaf with the node's own patch
    }
    if (w0 != 0) w0 |= encodeNodeError(errors[i], node.level) << kNodeErrorShift;
    blob[nodesAt + 2 * i] = w0;
    blob[nodesAt + 2 * i + 1] = w1;
  }
  std::copy(links.begin(), links.end(), blob.begin() + std::ptrdiff_t(linksAt));
  std::copy(records.begin(), records.end(), blob.begin() + std::ptrdiff_t(dataAt));
  return blob;
}

uint32_t blobPages(size_t words) {
  return uint32_t((words + gpu::kPageWords - 1) / gpu::kPageWords);
}

}  // namespace iso::viewer
