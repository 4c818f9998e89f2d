// Splat blobs and the splat index (splats.h).
#include "tracer/splats.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <glm/glm.hpp>
#include <glm/packing.hpp>
#include <functional>

#include "iso/quantize.h"
#include "iso/surface.h"
#include "shaders/shared.h"

namespace iso::viewer {
namespace {

using gpu::kNotResident;

constexpr double kGridCells = double(uint32_t{1} << kMaxLevel);

struct Box {
  glm::vec3 lo{1e30f}, hi{-1e30f};
  void add(const Box& b) {
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  void store(std::vector<uint32_t>& out) const {
    for (int a = 0; a < 3; ++a) out.push_back(std::bit_cast<uint32_t>(lo[a]));
    for (int a = 0; a < 3; ++a) out.push_back(std::bit_cast<uint32_t>(hi[a]));
  }
};

// The octahedral pair of a unit vector (the inverse of decodeOctahedral in shaders/rays.h).
glm::vec2 octahedral(glm::vec3 n) {
  n /= std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
  glm::vec2 p(n.x, n.y);
  if (n.z < 0.0f)
    p = glm::vec2((1.0f - std::abs(n.y)) * (n.x >= 0.0f ? 1.0f : -1.0f),
                  (1.0f - std::abs(n.x)) * (n.y >= 0.0f ? 1.0f : -1.0f));
  return p;
}

// The box of a disk: along axis a it reaches r·sqrt(1 - n_a²) from its center (r without a
// normal: a disk facing any ray).
Box diskBox(const glm::vec3& c, float r, const glm::vec3* n) {
  glm::vec3 reach(r);
  if (n != nullptr)
    for (int a = 0; a < 3; ++a) reach[a] = r * std::sqrt(std::max(0.0f, 1.0f - (*n)[a] * (*n)[a]));
  return {c - reach, c + reach};
}

Box cellBox(const ChunkInfo& c) {
  const auto xyz = mortonDecode(c.key);
  const float size = std::ldexp(1.0f, -int(c.level));
  const glm::vec3 lo = glm::vec3(float(xyz[0]), float(xyz[1]), float(xyz[2])) * size;
  return {lo, lo + glm::vec3(size)};
}

}  // namespace

// A points chunk's radius for files without stored radii (format 1.x): from its density.
static double densityRadius(const ChunkInfo& info) {
  return densityPointRadius(info.level, info.pointCount);
}

std::vector<uint32_t> buildSplatBlob(const PointsChunk& points, const ChunkInfo& info) {
  struct Splat {
    uint64_t key;
    glm::vec3 c;
    float r;
    glm::vec3 n;
    bool hasNormal;
    uint32_t rgb;
  };
  std::vector<Splat> splats;
  splats.reserve(points.size());
  const float fallback = float(densityRadius(info));
  for (size_t i = 0; i < points.size(); ++i) {
    const std::array<double, 3> u =
        pointFramePosition(info.level, info.key, points.stepBits, points.offsets[i]);
    if (!(u[0] >= 0.0 && u[1] >= 0.0 && u[2] >= 0.0 && u[0] < 1.0 && u[1] < 1.0 && u[2] < 1.0))
      continue;  // outside the frame: outliers the conversion removed
    Splat s;
    s.c = glm::vec3(float(u[0]), float(u[1]), float(u[2]));
    s.key = mortonEncode(uint32_t(u[0] * kGridCells), uint32_t(u[1] * kGridCells),
                         uint32_t(u[2] * kGridCells));
    s.r = kSplatRadiusScale *
          (points.radii.empty() ? fallback : float(decodePointRadius(points.radii[i])));
    s.n = glm::vec3(0.0f);
    if (!points.normals.empty())
      s.n = glm::vec3(decodeSnorm16(points.normals[i][0]), decodeSnorm16(points.normals[i][1]),
                      decodeSnorm16(points.normals[i][2]));
    s.hasNormal = glm::dot(s.n, s.n) > 0.25f;
    if (s.hasNormal) s.n = glm::normalize(s.n);
    s.rgb = 0x00FFFFFFu;
    if (!points.colors.empty()) {
      const auto& c = points.colors[i];
      // 16-bit sRGB to the 8-bit code (the colors the tracer decodes through its table).
      s.rgb = uint32_t((c[0] + 128) / 257) | uint32_t((c[1] + 128) / 257) << 8 |
              uint32_t((c[2] + 128) / 257) << 16;
    }
    splats.push_back(s);
  }
  std::sort(splats.begin(), splats.end(),
            [](const Splat& a, const Splat& b) { return a.key < b.key; });
  const uint32_t n = uint32_t(splats.size());
  // Box levels: level 0 bounds groups of kSplatBranch disks, each further level groups of boxes.
  std::vector<std::vector<Box>> levels;
  if (n > 0) {
    std::vector<Box> boxes((n + gpu::kSplatBranch - 1) / gpu::kSplatBranch);
    for (uint32_t i = 0; i < n; ++i)
      boxes[i / gpu::kSplatBranch].add(
          diskBox(splats[i].c, splats[i].r, splats[i].hasNormal ? &splats[i].n : nullptr));
    levels.push_back(std::move(boxes));
    while (levels.back().size() > 1) {
      const std::vector<Box>& below = levels.back();
      std::vector<Box> up((below.size() + gpu::kSplatBranch - 1) / gpu::kSplatBranch);
      for (size_t i = 0; i < below.size(); ++i) up[i / gpu::kSplatBranch].add(below[i]);
      levels.push_back(std::move(up));
    }
  }
  std::vector<uint32_t> blob(gpu::kSplatHeaderWords, 0);
  blob[gpu::kSplatCount] = n;
  blob[gpu::kSplatLevels] = uint32_t(levels.size());
  for (size_t l = 0; l < levels.size(); ++l) {
    blob[gpu::kSplatLevelFirst + l] = uint32_t(blob.size());
    blob[gpu::kSplatLevelCount + l] = uint32_t(levels[l].size());
    for (const Box& b : levels[l]) b.store(blob);
  }
  blob[gpu::kSplatPoints] = uint32_t(blob.size());
  for (const Splat& s : splats) {
    for (int a = 0; a < 3; ++a) blob.push_back(std::bit_cast<uint32_t>(s.c[a]));
    blob.push_back(std::bit_cast<uint32_t>(s.r));
    blob.push_back(s.hasNormal ? glm::packSnorm2x16(octahedral(s.n)) : 0u);
    blob.push_back(s.rgb | (s.hasNormal ? 0xFF000000u : 0u));
  }
  blob[gpu::kBlobWords] = uint32_t(blob.size());
  return blob;
}

std::optional<SplatIndex> buildSplatIndex(const Reader& reader) {
  const auto chunks = reader.chunks();
  // The points chunks with points inside the frame: all but the chunks of outliers (level 0,
  // no radius, no parent, no children) of files with radii.
  std::vector<std::vector<uint32_t>> children(chunks.size());
  std::vector<uint32_t> roots;
  std::vector<float> leafRadii;
  bool radii = false;  // (2.0 files: every chunk with points inside the frame has a radius)
  for (const ChunkInfo& c : chunks) {
    if (c.kind != kPointsKind) continue;
    if (c.parent != kNoParent) children[c.parent].push_back(c.id);
    radii = radii || c.geometricError > 0.0f;
  }
  for (const ChunkInfo& c : chunks) {
    if (c.kind != kPointsKind) continue;
    if (radii && c.geometricError == 0.0f) continue;  // only outliers outside the frame
    if (c.parent == kNoParent) roots.push_back(c.id);
    if (children[c.id].empty())
      leafRadii.push_back(c.geometricError > 0.0f ? c.geometricError : float(densityRadius(c)));
  }
  if (roots.empty()) return std::nullopt;
  // A chunk's reach: the largest radius, from the table (or the density for 1.x files).
  const auto reach = [&](const ChunkInfo& c) {
    return kSplatRadiusScale *
           (c.geometricError > 0.0f ? c.geometricError : float(densityRadius(c)) * 4.0f);
  };
  struct Node {
    Box box;
    uint32_t chunk = kNotResident;
    std::vector<uint32_t> kids;  // node numbers
  };
  std::vector<Node> nodes(1);  // node 0: the root
  // A node per chunk, breadth first; the roots' nodes grouped by eights in Morton order (files
  // without subsample chunks have a root per chunk).
  std::sort(roots.begin(), roots.end(), [&](uint32_t a, uint32_t b) {
    const ChunkInfo &x = chunks[a], &y = chunks[b];
    return (x.key << (3 * (kMaxLevel - x.level))) < (y.key << (3 * (kMaxLevel - y.level)));
  });
  std::vector<uint32_t> chunkNode(chunks.size(), kNotResident);
  const std::function<uint32_t(uint32_t)> make = [&](uint32_t chunk) -> uint32_t {
    const uint32_t at = uint32_t(nodes.size());
    nodes.emplace_back();
    nodes[at].chunk = chunk;
    const ChunkInfo& c = chunks[chunk];
    Box box = cellBox(c);
    const float grow = reach(c);
    box.lo -= glm::vec3(grow);
    box.hi += glm::vec3(grow);
    for (uint32_t child : children[chunk]) {
      const uint32_t k = make(child);
      nodes[at].kids.push_back(k);
      box.add(nodes[k].box);
    }
    nodes[at].box = box;
    return at;
  };
  std::vector<uint32_t> level;
  for (uint32_t r : roots) level.push_back(make(r));
  while (level.size() > 8) {
    std::vector<uint32_t> up;
    for (size_t i = 0; i < level.size(); i += 8) {
      const uint32_t at = uint32_t(nodes.size());
      nodes.emplace_back();
      for (size_t j = i; j < std::min(level.size(), i + 8); ++j) {
        nodes[at].kids.push_back(level[j]);
        nodes[at].box.add(nodes[level[j]].box);
      }
      up.push_back(at);
    }
    level = std::move(up);
  }
  for (uint32_t k : level) {
    nodes[0].kids.push_back(k);
    nodes[0].box.add(nodes[k].box);
  }
  // Lay the nodes out in preorder, each with the node after its subtree.
  std::vector<uint32_t> order, skip(nodes.size(), 0), parentChunk(nodes.size(), kNotResident);
  const std::function<void(uint32_t)> visit = [&](uint32_t i) {
    order.push_back(i);
    for (uint32_t k : nodes[i].kids) {
      parentChunk[k] = nodes[i].chunk;
      visit(k);
    }
    skip[i] = uint32_t(order.size());
  };
  visit(0);
  SplatIndex index;
  index.chunk = uint32_t(chunks.size());
  index.nodes = uint32_t(order.size());
  std::vector<uint32_t>& w = index.words;
  w.assign(4, 0);
  w[gpu::kSplatCount] = index.nodes;
  w[gpu::kSplatIndexNodes] = 4;
  for (uint32_t i : order) {
    const Node& node = nodes[i];
    node.box.store(w);
    w.push_back(node.chunk);
    w.push_back(skip[i]);
    w.push_back(parentChunk[i]);
    w.push_back(std::bit_cast<uint32_t>(node.chunk == kNotResident ? 0.0f : reach(chunks[node.chunk])));
  }
  w[gpu::kBlobWords] = uint32_t(w.size());
  std::nth_element(leafRadii.begin(), leafRadii.begin() + ptrdiff_t(leafRadii.size() / 2),
                   leafRadii.end());
  index.typicalRadius = leafRadii.empty() ? 0.0f : kSplatRadiusScale * leafRadii[leafRadii.size() / 2];
  return index;
}

}  // namespace iso::viewer
