// The point stages chunk by chunk (specs/pipeline.md, "Out of core"). Each chunk is loaded with
// the points of a box around it. A point's k nearest neighbours are exact when its k-NN ball
// lies inside the box; a chunk's results are exact when that holds for every point within a few
// k-NN hops of its own points (radii and outliers look at neighbours' k-NN distances, the repair
// of flipped input normals votes over four rounds). Otherwise the box widens and the chunk runs
// again. Orientation blocks nest in chunks, so each block propagates exactly as in core; the
// components are aligned across blocks once all chunks are done.
#include "outofcore.h"

#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <limits>

#include "progress.h"

namespace iso {
namespace {

// Whether point i's k-NN ball lies inside the box [lo, hi] (frame units); faces of the box on
// the frame cube's faces bound nothing.
bool ballInside(const glm::vec3& p, float radius, const glm::dvec3& lo, const glm::dvec3& hi) {
  const double r = double(radius) * (1.0 + 1e-5) + 1e-9;  // float rounding of the distance
  for (int a = 0; a < 3; ++a) {
    if (lo[a] > 0.0 && double(p[a]) - r <= lo[a]) return false;
    if (hi[a] < 1.0 && double(p[a]) + r >= hi[a]) return false;
  }
  return true;
}

struct Accumulated {
  PointSet points;
  std::vector<uint32_t> neighborSource;  // k per point: input index of each neighbour
  OrientationComponents components;      // `of` per point in `points`
  size_t blocks = 0;
  double spacingSum = 0.0;
  size_t duplicates = 0;
  NormalStats normals;
  std::vector<uint32_t> outlierSources;
  uint64_t haloPoints = 0, widenings = 0, maxLoaded = 0;
};

void appendRange(PointSet& to, const PointSet& from, uint32_t begin, uint32_t end) {
  const auto add = [&](auto& dst, const auto& src) {
    if (!src.empty()) dst.insert(dst.end(), src.begin() + begin, src.begin() + end);
  };
  add(to.position, from.position);
  add(to.normal, from.normal);
  add(to.color, from.color);
  add(to.weight, from.weight);
  add(to.radius, from.radius);
  add(to.roughness, from.roughness);
  add(to.key, from.key);
  add(to.source, from.source);
}

// Room for n points (an upper bound: duplicates merge), so that appending never doubles.
void reserveFor(Accumulated& a, size_t n, const PointLayout& layout, size_t k) {
  PointSet& p = a.points;
  p.position.reserve(n);
  p.normal.reserve(n);  // estimated where the input has none
  if (layout.colors) p.color.reserve(n);
  p.weight.reserve(n);
  p.radius.reserve(n);
  p.key.reserve(n);
  p.source.reserve(n);
  a.components.of.reserve(n);
  a.neighborSource.reserve(n * k);
}

class ChunkRunner {
 public:
  ChunkRunner(const Distribution& distribution, const Frame& frame, const BuildOptions& options,
              bool findingOutliers, bool inputNormals)
      : distribution_(distribution),
        frame_(frame),
        options_(options),
        findingOutliers_(findingOutliers),
        hops_(inputNormals ? 4 : 1) {}

  void run(const SpillChunk& chunk, Accumulated& out) {
    LoadedPoints own = distribution_.load(chunk);
    const double cell = std::ldexp(1.0, -chunk.level);
    const std::array<uint32_t, 3> c = mortonDecode(chunk.key);
    const glm::dvec3 cellLo(c[0] * cell, c[1] * cell, c[2] * cell);
    // A first guess of the halo: the k-NN radius of points spread over twice the cell's face
    // area, times the hops needed, with room to spare; widened when it is not enough.
    const double radius = std::sqrt(double(options_.neighbors) * 2.0 * cell * cell /
                                    (3.14159 * double(std::max<size_t>(own.source.size(), 1))));
    double width = std::min(cell / 8.0, 2.0 * (hops_ + 1) * radius);
    for (;;) {
      const glm::dvec3 lo = glm::max(cellLo - width, glm::dvec3(0.0));
      const glm::dvec3 hi = glm::min(cellLo + cell + width, glm::dvec3(1.0));
      const bool everything = lo == glm::dvec3(0.0) && hi == glm::dvec3(1.0);
      LoadedPoints halo = distribution_.loadBox(lo, hi, chunk);
      if (tryChunk(chunk, own, halo, lo, hi, everything, out)) return;
      ++out.widenings;
      width *= 2.0;
    }
  }

 private:
  bool tryChunk(const SpillChunk& chunk, const LoadedPoints& own, const LoadedPoints& halo,
                const glm::dvec3& lo, const glm::dvec3& hi, bool everything, Accumulated& out) {
    PointCloud cloud = own.cloud;
    const auto append = [](auto& dst, const auto& src) { dst.insert(dst.end(), src.begin(), src.end()); };
    append(cloud.positions, halo.cloud.positions);
    append(cloud.normals, halo.cloud.normals);
    append(cloud.colors, halo.cloud.colors);
    PointSet points = makePointSet(cloud, frame_);
    points.source = own.source;
    append(points.source, halo.source);
    sortByKey(points);
    mergeDuplicates(points);
    // The chunk's own points: its Morton key range.
    const int shift = 3 * (kMaxLevel - chunk.level);
    const auto ownBegin = uint32_t(
        std::lower_bound(points.key.begin(), points.key.end(), chunk.key << shift) -
        points.key.begin());
    const auto ownEnd = uint32_t(
        std::lower_bound(points.key.begin(), points.key.end(), (chunk.key + 1) << shift) -
        points.key.begin());
    const PointIndex index(points.position);
    Neighbors neighbors = findNeighbors(points, index, options_.neighbors);
    if (!everything && !isExact(points, neighbors, ownBegin, ownEnd, lo, hi)) return false;
    if (neighbors.k == 0) {  // one distinct point in the whole input: no surface (said later)
      appendRange(out.points, points, ownBegin, ownEnd);
      out.components.of.insert(out.components.of.end(), ownEnd - ownBegin, kNoNode);
      return true;
    }

    out.maxLoaded = std::max<uint64_t>(out.maxLoaded, points.size());
    out.haloPoints += points.size() - (ownEnd - ownBegin);
    out.duplicates += own.source.size() - (ownEnd - ownBegin);
    const size_t k = size_t(neighbors.k);
    if (findingOutliers_) {
      const std::vector<uint8_t> flagged = findOutliers(points, neighbors);
      for (uint32_t i = ownBegin; i < ownEnd; ++i)
        if (flagged[i]) out.outlierSources.push_back(points.source[i]);
    }
    estimateRadii(points, neighbors);
    for (uint32_t i = ownBegin; i < ownEnd; ++i) out.spacingSum += neighbors.distance[i * k];
    std::vector<uint8_t> wasEstimated(points.size(), 0);
    for (size_t i = 0; i < points.size(); ++i)
      wasEstimated[i] = points.normal.empty() || points.normal[i] == glm::vec3(0.0f);
    out.normals.estimated += size_t(std::count(wasEstimated.begin() + ownBegin,
                                               wasEstimated.begin() + ownEnd, uint8_t{1}));
    estimateNormals(points, neighbors);
    out.normals.flipped += repairFlippedNormals(points, neighbors, wasEstimated, ownBegin, ownEnd);
    OrientationComponents local;
    local.of.assign(points.size(), kNoNode);
    if (options_.orient == OrientMode::Up) {
      orientUp(points, wasEstimated, ownBegin, ownEnd);
    } else {
      const OrientationBlocks blocks =
          orientationBlocks(points, options_.orientBlockPoints, ownBegin, ownEnd, chunk.level);
      local.anchored.swap(out.components.anchored);
      local.seedHeight.swap(out.components.seedHeight);
      propagateInBlocks(points, neighbors, wasEstimated, blocks, local);
      local.anchored.swap(out.components.anchored);
      local.seedHeight.swap(out.components.seedHeight);
      out.blocks += blocks.size();
    }

    appendRange(out.points, points, ownBegin, ownEnd);
    out.components.of.insert(out.components.of.end(), local.of.begin() + ownBegin,
                             local.of.begin() + ownEnd);
    for (uint32_t i = ownBegin; i < ownEnd; ++i)
      for (size_t e = 0; e < k; ++e)
        out.neighborSource.push_back(points.source[neighbors.index[i * k + e]]);
    progressAdvance(own.source.size());
    return true;
  }

  // Whether every point within hops_ k-NN hops of the own points has its k-NN ball in the box.
  bool isExact(const PointSet& points, const Neighbors& neighbors, uint32_t ownBegin,
               uint32_t ownEnd, const glm::dvec3& lo, const glm::dvec3& hi) const {
    const size_t k = size_t(neighbors.k);
    if (k < size_t(options_.neighbors)) return false;  // too few points loaded
    std::vector<uint8_t> reached(points.size(), 0);
    std::vector<uint32_t> frontier;
    for (uint32_t i = ownBegin; i < ownEnd; ++i) {
      reached[i] = 1;
      frontier.push_back(i);
    }
    for (int hop = 0; hop <= hops_; ++hop) {
      std::vector<uint32_t> next;
      for (uint32_t i : frontier) {
        if (!ballInside(points.position[i], neighbors.distance[i * k + k - 1], lo, hi))
          return false;
        if (hop == hops_) continue;
        for (size_t e = 0; e < k; ++e) {
          const uint32_t j = neighbors.index[i * k + e];
          if (!reached[j]) {
            reached[j] = 1;
            next.push_back(j);
          }
        }
      }
      frontier.swap(next);
    }
    return true;
  }

  const Distribution& distribution_;
  const Frame& frame_;
  const BuildOptions& options_;
  bool findingOutliers_;
  int hops_;
};

}  // namespace

ReadyPoints prepareOutOfCore(const RawSpill& raw, SpillDirectory& directory,
                             const BuildOptions& options, uint64_t maxChunkPoints,
                             const std::function<void(const std::string&, uint64_t)>& stage) {
  if (raw.size() >= uint64_t(std::numeric_limits<uint32_t>::max()))
    throw std::length_error("more than 4,294,967,294 input points in one conversion");
  // Orientation blocks must nest in chunks: a chunk holds at least a block's points.
  maxChunkPoints = std::max<uint64_t>(maxChunkPoints, options.orientBlockPoints);
  ReadyPoints ready;
  ready.frame = chooseFrame(raw.lo(), raw.hi());
  std::vector<uint8_t> keep;
  bool findingOutliers = options.removeOutliers;
  uint64_t peakTemporary = 0;
  Accumulated done;
  size_t chunks = 0;
  for (;;) {
    stage("distribute", 2 * raw.size());
    const Distribution distribution(directory, raw, ready.frame, maxChunkPoints,
                                    keep.empty() ? nullptr : &keep);
    peakTemporary = std::max(peakTemporary, directory.bytes());
    chunks = distribution.chunks().size();
    stage("points", distribution.size());
    done = Accumulated{};
    reserveFor(done, distribution.size(), raw.layout(), size_t(options.neighbors));
    ChunkRunner runner(distribution, ready.frame, options, findingOutliers, raw.layout().normals);
    for (const SpillChunk& chunk : distribution.chunks()) runner.run(chunk, done);
    if (done.outlierSources.empty()) break;
    // Far outliers waste the frame's precision: choose it again without them, as in core.
    ready.outliers = done.outlierSources.size();
    keep.assign(raw.size(), 1);
    for (uint32_t s : done.outlierSources) keep[s] = 0;
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    raw.forEachBatch([&](const PointCloud& batch, uint64_t first) {
      for (size_t i = 0; i < batch.size(); ++i)
        if (keep[first + i]) {
          lo = glm::min(lo, batch.positions[i]);
          hi = glm::max(hi, batch.positions[i]);
        }
    });
    ready.frame = chooseFrame(lo, hi);
    findingOutliers = false;
  }

  stage("orient", done.points.size());
  PointSet& points = done.points;
  const size_t n = points.size();
  const size_t k = n > 0 ? done.neighborSource.size() / n : 0;
  {
    // The neighbours as indices into the assembled points.
    std::vector<uint32_t> ordinal(raw.size(), kNoNode);
    for (size_t i = 0; i < n; ++i) ordinal[points.source[i]] = uint32_t(i);
    Neighbors neighbors;
    neighbors.k = int(k);
    neighbors.index.resize(done.neighborSource.size());
    for (size_t e = 0; e < done.neighborSource.size(); ++e)
      neighbors.index[e] = ordinal[done.neighborSource[e]];
    done.neighborSource = {};
    if (options.orient != OrientMode::Up && done.blocks > 1 && done.normals.estimated > 0)
      alignComponents(points.normal, done.components, neighbors.index, k);
    // Roughness compares a point's normal with its neighbours': after they are all oriented.
    estimateRoughness(points, neighbors);
  }
  progressAdvance(n);

  ready.radii.meanSpacing = n > 0 ? done.spacingSum / double(n) : 0.0;
  std::vector<float> radii = points.radius;
  ready.radii.medianRadius = medianOf(radii);
  ready.normals = done.normals;
  ready.duplicates = done.duplicates;
  ready.points = std::move(points);
  ready.index = std::make_unique<PointIndex>(ready.points.position);

  size_t kept = 0;
  for (uint64_t i = 0; i < raw.size(); ++i) kept += keep.empty() || keep[i] ? 1 : 0;
  const size_t step = sampleStep(kept, kAccuracySamples);
  size_t ordinalKept = 0;
  raw.forEachBatch([&](const PointCloud& batch, uint64_t first) {
    for (size_t i = 0; i < batch.size(); ++i) {
      if (!keep.empty() && !keep[first + i]) continue;
      if (ordinalKept++ % step == 0) ready.sample.push_back(batch.positions[i]);
    }
  });
  ready.outOfCore = {{"chunks", chunks},
                     {"max_chunk_points", maxChunkPoints},
                     {"largest_loaded_points", done.maxLoaded},
                     {"halo_points", done.haloPoints},
                     {"halo_widenings", done.widenings},
                     {"temporary_bytes_peak", peakTemporary}};
  return ready;
}

}  // namespace iso
