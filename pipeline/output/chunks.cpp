// Cutting the octree into file chunks and writing them (specs/pipeline.md, "Chunks";
// specs/iso-format.md, "Surface chunks"). A chunk holds the nodes of one octree cell over a range
// of levels, about `chunkNodes` of them: the top chunk holds the coarse levels, each chunk below it
// refines the nodes at its parent's last level. Chunks are written parents first.
#include "pipeline/output/chunks.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "iso/check.h"
#include "iso/reader.h"
#include "iso/writer.h"
#include "pipeline/base/buffers.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"

namespace iso {
namespace {

class ChunkPlanner {
 public:
  ChunkPlanner(const Octree& tree, uint32_t budget)
      : tree_(tree), budget_(std::max<uint32_t>(budget, 1)) {
    subtree_.assign(tree.nodes.size(), 0);
    for (size_t i = tree.nodes.size(); i-- > 0;) {
      const OctreeNode& node = tree.nodes[i];
      if (node.kind == NodeKind::Empty) continue;
      subtree_[i] = 1;
      if (node.kind == NodeKind::Internal)
        for (uint32_t c = 0; c < 8; ++c) subtree_[i] += subtree_[node.firstChild + c];
    }
  }

  std::vector<ChunkPlan> plan() {
    if (!tree_.nodes.empty() && tree_.nodes[0].kind != NodeKind::Empty) emit(0, 0, {0}, kNoParent);
    return std::move(plans_);
  }

 private:
  std::vector<uint32_t> children(uint32_t id) const {
    std::vector<uint32_t> out;
    const OctreeNode& node = tree_.nodes[id];
    if (node.kind != NodeKind::Internal) return out;
    for (uint32_t c = 0; c < 8; ++c)
      if (tree_.nodes[node.firstChild + c].kind != NodeKind::Empty)
        out.push_back(node.firstChild + c);
    return out;
  }

  uint8_t childMask(uint32_t id) const {
    uint8_t mask = 0;
    const OctreeNode& node = tree_.nodes[id];
    if (node.kind == NodeKind::Internal)
      for (uint32_t c = 0; c < 8; ++c)
        if (tree_.nodes[node.firstChild + c].kind != NodeKind::Empty) mask |= uint8_t(1u << c);
    ISO_CHECK(mask != 0 || node.isFilled());  // a node without children is a filled leaf
    return mask;
  }

  // Roots: nodes at one level inside the cell (cellLevel, cellKey), in key order.
  void emit(uint8_t cellLevel, uint64_t cellKey, const std::vector<uint32_t>& roots,
            uint32_t parent) {
    uint64_t total = 0;
    for (uint32_t r : roots) total += subtree_[r];
    const uint8_t start = tree_.nodes[roots[0]].level;
    if (total > budget_ && start > cellLevel) {  // several roots: split the cell
      emitBySubcell(cellLevel, cellKey, roots, parent);
      return;
    }
    // Take whole levels while they fit the budget (at least one).
    std::vector<std::vector<uint32_t>> levels = {roots};
    uint64_t count = roots.size();
    for (;;) {
      std::vector<uint32_t> next;
      for (uint32_t id : levels.back())
        for (uint32_t c : children(id)) next.push_back(c);
      if (next.empty() || count + next.size() > budget_) {
        const uint32_t id = addPlan(cellLevel, cellKey, levels, parent);
        if (!next.empty()) emitBySubcell(cellLevel, cellKey, next, id);
        return;
      }
      count += next.size();
      levels.push_back(std::move(next));
    }
  }

  void emitBySubcell(uint8_t cellLevel, uint64_t cellKey, const std::vector<uint32_t>& roots,
                     uint32_t parent) {
    const uint8_t start = tree_.nodes[roots[0]].level;
    const int shift = 3 * (start - cellLevel - 1);
    for (uint64_t o = 0; o < 8; ++o) {
      const uint64_t subKey = cellKey << 3 | o;
      std::vector<uint32_t> group;
      for (uint32_t r : roots)
        if ((tree_.nodes[r].key >> shift) == subKey) group.push_back(r);
      if (!group.empty()) emit(uint8_t(cellLevel + 1), subKey, group, parent);
    }
  }

  uint32_t addPlan(uint8_t cellLevel, uint64_t cellKey,
                   const std::vector<std::vector<uint32_t>>& levels, uint32_t parent) {
    ChunkPlan plan;
    plan.cellLevel = cellLevel;
    plan.cellKey = cellKey;
    plan.parent = parent;
    plan.topology.startLevel = tree_.nodes[levels[0][0]].level;
    plan.topology.depth = uint8_t(levels.size());
    for (uint32_t r : levels[0]) plan.topology.rootKeys.push_back(tree_.nodes[r].key);
    for (const auto& level : levels)
      for (uint32_t id : level) {
        plan.nodes.push_back(id);
        plan.topology.childMasks.push_back(childMask(id));
      }
    plans_.push_back(std::move(plan));
    return uint32_t(plans_.size() - 1);
  }

  const Octree& tree_;
  uint32_t budget_;
  SpillVector<uint64_t> subtree_;  // per node, like the tree's nodes
  std::vector<ChunkPlan> plans_;
};

CornerValues leafValues(const CornerLayout& layout, const CornerField& field,
                        const SpillVector<uint32_t>& hangingOf, const HangingCorners& hanging,
                        const AttributeDesc& distance, bool colors) {
  CornerValues v;
  const size_t n = layout.leafCorners.size();
  v.distance.resize(n);
  v.normal.resize(n);
  if (colors) v.color.resize(n);
  FlatMap<Key128, uint32_t> local(n);
  for (uint32_t i = 0; i < n; ++i) local.insert(gridKey(layout.leafCorners[i].point), i);
  const auto levelOf = [&](uint32_t entry) {  // the scale a reader of this chunk will use
    const uint32_t* i = local.find(field.index.key(entry));
    return i ? layout.leafCorners[*i].level : field.coarsestLevel[entry];
  };
  for (uint32_t i = 0; i < n; ++i) {
    // A chunk's corners are scattered over the field's arrays: one chunk maps many pages.
    if (i % 1024 == 0) spillPause();
    const uint32_t entry = field.find(layout.leafCorners[i].point);
    const CornerSample& s = field.value[entry];
    v.distance[i] = s.distance;
    v.normal[i] = {s.normal.x, s.normal.y, s.normal.z};
    if (colors) v.color[i] = {s.color.x, s.color.y, s.color.z};
    if (hangingOf[entry] == kNoNode) continue;
    // Snap on the values a reader decodes, so that the quantized patches agree as well.
    const HangingCorner& h = hanging[hangingOf[entry]];
    float sum = 0.0f;
    for (int k = 0; k < h.sourceCount; ++k) {
      const uint32_t src = h.sources[size_t(k)];
      sum += roundTripDistance(field.value[src].distance, levelOf(src), distance);
    }
    v.distance[i] = sum / float(h.sourceCount);
  }
  return v;
}

CornerValues lodValues(const CornerLayout& layout, const LodField& lod, bool colors) {
  CornerValues v;
  for (size_t i = 0; i < layout.lodCorners.size(); ++i) {
    if (i % 1024 == 0) spillPause();
    const CornerKey& k = layout.lodCorners[i];
    const CornerSample& s = lod.value[lod.find(k.level, k.point)];
    v.distance.push_back(s.distance);
    v.normal.push_back({s.normal.x, s.normal.y, s.normal.z});
    if (colors) v.color.push_back({s.color.x, s.color.y, s.color.z});
  }
  return v;
}

}  // namespace

std::vector<ChunkPlan> planChunks(const Octree& tree, uint32_t nodeBudget) {
  return ChunkPlanner(tree, nodeBudget).plan();
}

FileHeader surfaceHeader(const Frame& frame, uint8_t maxLevel, bool colors, int normalBits) {
  FileHeader header;
  header.frame = frame;
  header.maxLevel = maxLevel;
  header.attributes = {
      kDistanceEncoding,
      {Semantic::Normal, normalBits > 8 ? Encoding::Oct24 : Encoding::Oct16, 2, 0.0f}};
  if (colors) header.attributes.push_back({Semantic::Color, Encoding::Srgb8, 3, 0.0f});
  return header;
}

WriteStats writeSurfaceFile(const std::filesystem::path& output, const WriteInput& in,
                            const std::function<std::string(const std::filesystem::path&,
                                                            const WriteStats&)>& finalMetadata) {
  const Octree& tree = *in.tree;
  uint8_t maxLevel = 0;
  for (const OctreeNode& node : tree.nodes)
    if (node.kind != NodeKind::Empty) maxLevel = std::max(maxLevel, node.level);
  const FileHeader header = surfaceHeader(in.frame, maxLevel, in.colors, in.options.normalBits);
  SpillVector<uint32_t> hangingOf(in.corners->size(), kNoNode);  // per corner entry
  for (uint32_t i = 0; i < in.hanging->size(); ++i) hangingOf[(*in.hanging)[i].corner] = i;

  Writer writer(output, header, {.zstdLevel = in.options.zstdLevel});
  WriteStats stats;
  // A file chunk: its description and payload, encoded from the plan.
  struct Encoded {
    ChunkDesc desc;
    std::vector<std::byte> payload;
    uint64_t leafCorners = 0, lodCorners = 0;
  };
  const auto encode = [&](ChunkPlan& plan) {
    Encoded out;
    double inputPoints = 0.0;  // weights count merged duplicates: whole numbers, summed exactly
    for (uint64_t key : plan.topology.rootKeys) {
      const OctreeNode& root = tree.nodes[tree.find(plan.topology.startLevel, key)];
      for (uint32_t i = root.pointBegin; i < root.pointEnd; ++i) {
        if ((i - root.pointBegin) % 65536 == 0) spillPause();  // (the top chunk: every point)
        inputPoints += in.points->weight[i];
      }
    }
    plan.pointCount = uint64_t(std::llround(inputPoints));
    const CornerLayout layout =
        layoutSurface(plan.topology, plan.cellLevel, plan.cellKey, header.maxLevel);
    const CornerValues leaf =
        leafValues(layout, *in.corners, hangingOf, *in.hanging, header.attributes[0], in.colors);
    const CornerValues lod = lodValues(layout, *in.lod, in.colors);
    out.payload = encodeSurfaceChunk(plan.topology, layout, header.attributes, leaf, lod);
    ChunkDesc& desc = out.desc;
    desc.kind = kSurfaceKind;
    desc.level = plan.cellLevel;
    desc.key = plan.cellKey;
    desc.parent = plan.parent;
    desc.pointCount = plan.pointCount;
    desc.nodeCount = uint32_t(plan.nodes.size());
    for (const SurfaceNode& node : layout.nodes) desc.leafCount += node.isLeaf() ? 1 : 0;
    for (size_t i = 0; i < layout.nodes.size(); ++i)
      if (!layout.nodes[i].isLeaf() &&
          layout.nodes[i].firstChild == kNoNode)  // children in other chunks
        desc.geometricError =
            std::max(desc.geometricError, nodePatchError(tree, *in.points, *in.lod, plan.nodes[i]));
    out.leafCorners = layout.leafCorners.size();
    out.lodCorners = layout.lodCorners.size();
    return out;
  };
  // Encoded in parallel, a batch at a time, and written in plan order.
  std::vector<ChunkPlan> plans = planChunks(tree, in.options.chunkNodes);
  constexpr size_t kBatch = 64;
  for (size_t first = 0; first < plans.size(); first += kBatch) {
    const size_t count = std::min(kBatch, plans.size() - first);
    std::vector<Encoded> batch(count);
    tbb::parallel_for(size_t{0}, count, [&](size_t i) {
      spillPause();
      batch[i] = encode(plans[first + i]);
    });
    for (const Encoded& e : batch) {
      writer.addChunk(e.desc, e.payload);
      ++stats.chunks;
      stats.leafCorners += e.leafCorners;
      stats.lodCorners += e.lodCorners;
    }
  }
  if (in.release) in.release();  // the measure below decodes the file: not two surfaces at once
  if (in.moreChunks) {
    const uint32_t before = writer.chunkCount();
    in.moreChunks(writer, header);
    stats.chunks += writer.chunkCount() - before;
  }
  const auto bytesWithoutMetadata = [&](const Writer& w) {
    return w.bytesWritten() + uint64_t(stats.chunks) * kChunkEntrySize + kTrailerSize;
  };
  stats.fileBytesWithoutMetadata = bytesWithoutMetadata(writer);
  writer.setMetadata(in.metadata);
  writer.close();
  // The passes over the finished file: each copies the file so far into the next writer.
  Writer current = std::move(writer);
  FileHeader passHeader = header;
  for (const WritePass& pass : in.passes) {
    passHeader = pass.header(passHeader);
    Writer next(output, passHeader, {.zstdLevel = in.options.zstdLevel});
    pass.run(Reader::open(current.temporaryPath()), next);
    current.abandon();
    stats.chunks = next.chunkCount();
    stats.fileBytesWithoutMetadata = bytesWithoutMetadata(next);
    next.setMetadata(in.metadata);
    next.close();
    current = std::move(next);
  }
  current.replaceMetadata(finalMetadata(current.temporaryPath(), stats));
  current.commit();
  return stats;
}

}  // namespace iso
