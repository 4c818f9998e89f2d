#include "pipeline/analysis/measure.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <numeric>
#include <unordered_map>

#include "iso/reader.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {

namespace {

// Distances (world units) of points to the zero set, -1 where none was found; escaped[i] set where
// the projection left the model's region (then distance[i] is left alone); projected[i] the point
// of the zero set (frame units) when asked for.
void project(const SurfaceModel& surface, const Frame& frame, std::span<const glm::dvec3> points,
             std::span<const uint32_t> which, std::vector<double>& distance,
             std::vector<uint8_t>* escaped, std::vector<std::optional<Vec3>>* projected) {
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, which.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t j = r.begin(); j < r.end(); ++j) {
          const uint32_t i = which[j];
          const glm::dvec3 p = toFrame(points[i], frame);
          bool left = false;
          const std::optional<Vec3> x = surface.project({p.x, p.y, p.z}, &left);
          if (left) {
            (*escaped)[i] = 1;
            continue;
          }
          if (x) distance[i] = glm::length(glm::dvec3((*x)[0], (*x)[1], (*x)[2]) - p) * frame.size;
          if (projected) (*projected)[i] = x;
        }
      });
}

// Decoded surface chunks kept for reuse: pinned ones for good, the others while their bytes fit
// in a budget, the least recently used dropped first.
class DecodedChunks {
 public:
  DecodedChunks(const Reader& reader, uint64_t budget) : reader_(reader), budget_(budget) {}

  // Decode those of `ids` not held yet, in parallel, while they fit (all when pinned).
  void decode(std::span<const uint32_t> ids, bool pin) {
    std::vector<uint32_t> missing;
    uint64_t room = budget_ > bytes_ ? budget_ - bytes_ : 0;
    for (const uint32_t id : ids) {
      if (held_.contains(id)) continue;
      const uint64_t estimate = uint64_t(reader_.chunk(id).nodeCount) * kBytesPerNode;
      if (!pin && estimate > room) break;
      room -= std::min(room, estimate);
      missing.push_back(id);
    }
    std::vector<std::shared_ptr<const SurfaceChunk>> chunks(missing.size());
    tbb::parallel_for(size_t{0}, missing.size(), [&](size_t j) {
      chunks[j] = std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader_, missing[j]));
    });
    for (size_t j = 0; j < missing.size(); ++j) keep(missing[j], std::move(chunks[j]), pin);
  }

  std::shared_ptr<const SurfaceChunk> get(uint32_t id) {
    const auto found = held_.find(id);
    if (found != held_.end()) {
      found->second.used = ++clock_;
      return found->second.chunk;
    }
    auto chunk = std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader_, id));
    keep(id, chunk, false);
    return chunk;
  }

 private:
  // Decoded bytes a node takes, about (the node, and its share of corner keys and values): for
  // the estimate before decoding.
  static constexpr uint64_t kBytesPerNode = 160;
  struct Held {
    std::shared_ptr<const SurfaceChunk> chunk;
    uint64_t bytes = 0, used = 0;
    bool pinned = false;
  };

  void keep(uint32_t id, std::shared_ptr<const SurfaceChunk> chunk, bool pin) {
    const uint64_t bytes = bytesOf(*chunk);
    held_[id] = {std::move(chunk), bytes, ++clock_, pin};
    bytes_ += bytes;
    while (bytes_ > budget_) {
      auto oldest = held_.end();
      for (auto it = held_.begin(); it != held_.end(); ++it)
        if (!it->second.pinned && (oldest == held_.end() || it->second.used < oldest->second.used))
          oldest = it;
      if (oldest == held_.end()) break;
      bytes_ -= oldest->second.bytes;
      held_.erase(oldest);
    }
  }

  static uint64_t bytesOf(const SurfaceChunk& c) {
    const auto values = [](const CornerValues& v) {
      return v.distance.size() * sizeof(float) + v.normal.size() * sizeof(v.normal[0]) +
             v.color.size() * sizeof(v.color[0]) + v.occlusion.size() * sizeof(float);
    };
    return c.topology.childMasks.size() + c.topology.rootKeys.size() * sizeof(uint64_t) +
           c.layout.nodes.size() * sizeof(SurfaceNode) +
           (c.layout.leafCorners.size() + c.layout.lodCorners.size()) * sizeof(CornerKey) +
           values(c.leafValues) + values(c.lodValues);
  }

  const Reader& reader_;
  uint64_t budget_, bytes_ = 0, clock_ = 0;
  std::unordered_map<uint32_t, Held> held_;
};

DistanceStats statsOf(const std::vector<double>& distance, bool keepValues) {
  DistanceStats stats;
  stats.samples = distance.size();
  double sum = 0.0, squares = 0.0;
  for (double d : distance) {
    if (d < 0.0) {
      ++stats.unprojected;
      continue;
    }
    sum += d;
    squares += d * d;
    stats.max = std::max(stats.max, d);
    if (keepValues) stats.values.push_back(d);
  }
  const double n = double(stats.samples - stats.unprojected);
  if (n > 0) {
    stats.mean = sum / n;
    stats.rms = std::sqrt(squares / n);
  }
  return stats;
}

}  // namespace

DistanceStats pointsToZeroSet(const SurfaceModel& surface, const Frame& frame,
                              std::span<const glm::dvec3> points, bool keepValues,
                              std::vector<std::optional<Vec3>>* projected) {
  std::vector<double> distance(points.size(), -1.0);
  std::vector<uint32_t> all(points.size());
  std::iota(all.begin(), all.end(), 0u);
  if (projected) projected->assign(points.size(), std::nullopt);
  project(surface, frame, points, all, distance, nullptr, projected);
  return statsOf(distance, keepValues);
}

DistanceStats pointsToZeroSet(const Reader& reader, const Frame& frame,
                              std::span<const glm::dvec3> points, bool keepValues,
                              uint64_t regionLeaves) {
  uint64_t leaves = 0;
  for (const ChunkInfo& info : reader.chunks()) leaves += info.leafCount;
  uint8_t level = 0;  // a surface meets about 4^level cells of a level
  while (level < 7 && (uint64_t{1} << (2 * level)) * regionLeaves < leaves) ++level;
  const double edge = std::ldexp(1.0, -level);
  // The points of each cell, cells in key order.
  std::map<uint64_t, std::vector<uint32_t>> cells;
  for (uint32_t i = 0; i < points.size(); ++i) {
    const glm::vec3 p(toFrame(points[i], frame));
    cells[keyOf(p) >> (3 * (kMaxLevel - level))].push_back(i);
  }
  // Chunks of cells coarser than the regions' meet many of them: decoded once, up front, and kept.
  // The others are kept while they fit in half a region's budget, for the next regions (in key
  // order, neighbours) and the wider boxes of the same region, which meet most of them again.
  std::vector<uint32_t> coarse;
  for (const ChunkInfo& info : reader.chunks())
    if (info.kind == kSurfaceKind && info.level < level) coarse.push_back(info.id);
  DecodedChunks decoded(reader, regionLeaves * kDecodedLeafBytes / 2);
  decoded.decode(coarse, true);
  const SurfaceModel::ChunkSource source = [&](uint32_t id) { return decoded.get(id); };
  // One region at a time: a region's surface is what the measure holds besides the file (two at
  // once took the 100M dragon's conversion to 1.3 GiB under --memory 1G).
  std::vector<double> distance(points.size(), -1.0);
  std::vector<uint8_t> escaped(points.size(), 0);
  for (auto& [key, which] : cells) {
    const auto cell = mortonDecode(key);
    for (double margin = edge / 16; !which.empty(); margin *= 2.0) {
      SurfaceModel::Region region;
      for (size_t a = 0; a < 3; ++a) {
        region.lo[a] = double(cell[a]) * edge - margin;
        region.hi[a] = double(cell[a] + 1) * edge + margin;
      }
      bool whole = true;  // the box holds the frame's cube: the whole model, without checks
      for (size_t a = 0; a < 3; ++a) whole = whole && region.lo[a] <= 0.0 && region.hi[a] >= 1.0;
      const std::optional<SurfaceModel::Region> box = whole ? std::nullopt : std::optional(region);
      decoded.decode(SurfaceModel::chunksFor(reader, box), false);
      const SurfaceModel surface = SurfaceModel::load(reader, box, source);
      project(surface, frame, points, which, distance, &escaped, nullptr);
      std::erase_if(which, [&](uint32_t i) { return !escaped[i]; });
      for (const uint32_t i : which) escaped[i] = 0;
    }
  }
  return statsOf(distance, keepValues);
}

std::vector<glm::dvec3> samplePoints(const PointCloud& cloud, size_t limit) {
  const size_t n = cloud.size();
  const size_t step = std::max<size_t>(1, (n + limit - 1) / std::max<size_t>(limit, 1));
  std::vector<glm::dvec3> out;
  for (size_t i = 0; i < n; i += step) out.push_back(cloud.positions[i]);
  return out;
}

double pointSpacing(const PointCloud& cloud) {
  if (cloud.size() < 2) return 0.0;
  const Frame frame = chooseFrame(cloud);
  PointSet points = makePointSet(cloud, frame);
  sortByKey(points);
  mergeDuplicates(points);
  if (points.size() < 2) return 0.0;
  const PointIndex tree(points.position);
  Neighbors neighbors = findNeighbors(points, tree, 1);
  return double(medianOf(std::span<float>(neighbors.distance.data(), neighbors.distance.size()))) *
         frame.size;
}

}  // namespace iso
