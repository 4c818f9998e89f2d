#include "pipeline/analysis/measure.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <numeric>

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
  // Chunks of cells coarser than the regions' meet many of them: decoded once, up front.
  std::vector<uint32_t> coarseIds;
  for (const ChunkInfo& info : reader.chunks())
    if (info.kind == kSurfaceKind && info.level < level) coarseIds.push_back(info.id);
  std::vector<std::shared_ptr<const SurfaceChunk>> coarseChunks(coarseIds.size());
  tbb::parallel_for(size_t{0}, coarseIds.size(), [&](size_t j) {
    coarseChunks[j] =
        std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader, coarseIds[j]));
  });
  std::map<uint32_t, std::shared_ptr<const SurfaceChunk>> coarse;
  for (size_t j = 0; j < coarseIds.size(); ++j) coarse[coarseIds[j]] = coarseChunks[j];
  const SurfaceModel::ChunkSource source = [&](uint32_t id) {
    const auto cached = coarse.find(id);
    if (cached != coarse.end()) return cached->second;
    return std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader, id));
  };
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
      const SurfaceModel surface =
          SurfaceModel::load(reader, whole ? std::nullopt : std::optional(region), source);
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
