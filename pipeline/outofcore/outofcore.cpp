// The point stages chunk by chunk (specs/pipeline.md, "Out of core"). Each chunk is loaded with
// the points of a box around it. A point's k nearest neighbours are exact when its k-NN ball
// lies inside the box; a chunk's results are exact when that holds for every point within a few
// k-NN hops of its own points (radii and outliers look at neighbours' k-NN distances, the repair
// of flipped input normals votes over four rounds). Otherwise the box widens and the chunk runs
// again. Orientation blocks nest in chunks, so each block propagates exactly as in core; the
// components are aligned across blocks once all chunks are done.
#include "pipeline/outofcore/outofcore.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/common.hpp>
#include <limits>
#include <map>
#include <thread>
#include <type_traits>

#include "iso/check.h"
#include "pipeline/base/checkpoint.h"
#include "pipeline/base/files.h"
#include "pipeline/base/options.h"
#include "pipeline/base/progress.h"
#include "pipeline/points/points.h"

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

// What one chunk added to the accumulated results, so that it can be reused.
struct ChunkRecord {
  size_t pointBegin = 0, pointEnd = 0;  // in Accumulated::points
  uint32_t componentBegin = 0, componentEnd = 0;
  size_t boundaryBegin = 0, boundaryEnd = 0;  // in Accumulated::boundarySource
  size_t duplicates = 0, blocks = 0;
  NormalStats normals;
  glm::dvec3 lo{0.0}, hi{0.0};  // the box it was loaded with
};

struct Accumulated {
  PointSet points;
  SpillVector<float> firstDistance;  // per point: distance to its nearest neighbour
  // Points with a neighbour in another orientation component (or loaded in a halo): their
  // roughness is computed again, and their edges align the components, once all chunks are done.
  SpillVector<uint32_t> boundarySource;                 // input index of each
  UninitializedSpillVector<uint32_t> boundaryNeighbor;  // k per boundary point: input indices
  size_t k = 0;  // neighbours per point (fewer than asked when the input has few points)
  OrientationComponents components;  // `of` per point in `points`
  std::vector<ChunkRecord> chunks;
  // While finding strays: the groups of the points, named by their place in `points` (Morton
  // order, so that the groups' table is read where it was just written), each point's k-th
  // distance, and the near edges to points of other chunks: (place, input index of the other),
  // joined once every point has its place.
  std::unique_ptr<PointGroups> groups;
  SpillVector<float> kth;
  SpillVector<std::array<uint32_t, 2>> edgesOut;
  uint64_t haloPoints = 0, widenings = 0, maxLoaded = 0;
};

void appendRange(PointSet& to, const PointSet& from, uint32_t begin, uint32_t end) {
  PointSet::forEachColumn(
      [&](auto& dst, const auto& src) {
        if (!src.empty()) dst.insert(dst.end(), src.begin() + begin, src.begin() + end);
      },
      to, from);
}

// Room for n points (an upper bound: duplicates merge), so that appending never doubles.
void reserveFor(Accumulated& a, size_t n, const PointLayout& layout) {
  PointSet& p = a.points;
  // Every column (normals are estimated where the input has none) but colors the input lacks.
  PointSet::forEachColumn(
      [&](auto& column) {
        if (static_cast<const void*>(&column) != &p.color || layout.colors) column.reserve(n);
      },
      p);
  a.components.of.reserve(n);
  a.firstDistance.reserve(n);
}

// Rebuilds accumulated results chunk by chunk in place: each chunk's results are written at a
// cursor that never passes the chunk's old position (a chunk prepared again has its old points
// less the outliers), so the old results and the new ones are never held twice.
class InPlaceResults {
 public:
  explicit InPlaceResults(Accumulated& target) : to_(target) {}

  // Write the results of `record` in `from` (the target itself, or a chunk prepared again).
  void place(const Accumulated& from, ChunkRecord record) {
    const size_t begin = record.pointBegin, end = record.pointEnd, n = end - begin;
    const auto put = [&](auto& dst, const auto& src) {
      if (src.empty()) return;
      ISO_CHECK(cursor_ + n <= dst.size());
      std::copy(src.begin() + ptrdiff_t(begin), src.begin() + ptrdiff_t(end),
                dst.begin() + ptrdiff_t(cursor_));  // forward: safe moving down
    };
    PointSet::forEachColumn(put, to_.points, from.points);
    put(to_.firstDistance, from.firstDistance);
    const size_t firstBoundary = boundarySource_.size();
    boundarySource_.insert(boundarySource_.end(),
                           from.boundarySource.begin() + ptrdiff_t(record.boundaryBegin),
                           from.boundarySource.begin() + ptrdiff_t(record.boundaryEnd));
    boundaryNeighbor_.insert(
        boundaryNeighbor_.end(),
        from.boundaryNeighbor.begin() + ptrdiff_t(record.boundaryBegin * from.k),
        from.boundaryNeighbor.begin() + ptrdiff_t(record.boundaryEnd * from.k));
    record.boundaryBegin = firstBoundary;
    record.boundaryEnd = boundarySource_.size();
    const auto firstComponent = uint32_t(anchored_.size());
    for (size_t i = 0; i < n; ++i) {
      const uint32_t of = from.components.of[begin + i];
      to_.components.of[cursor_ + i] =
          of == kNoNode ? kNoNode : of - record.componentBegin + firstComponent;
    }
    anchored_.insert(anchored_.end(), from.components.anchored.begin() + record.componentBegin,
                     from.components.anchored.begin() + record.componentEnd);
    seedVote_.insert(seedVote_.end(), from.components.seedVote.begin() + record.componentBegin,
                     from.components.seedVote.begin() + record.componentEnd);
    record.pointBegin = cursor_;
    record.pointEnd = cursor_ + n;
    record.componentBegin = firstComponent;
    record.componentEnd = uint32_t(anchored_.size());
    records_.push_back(record);
    cursor_ += n;
  }

  // Cut the target to the results placed.
  void finish() {
    const auto cut = [&](auto& v) {
      if (!v.empty()) v.resize(cursor_);
    };
    PointSet::forEachColumn(cut, to_.points);
    cut(to_.firstDistance);
    to_.boundarySource = std::move(boundarySource_);
    to_.boundaryNeighbor = std::move(boundaryNeighbor_);
    cut(to_.components.of);
    to_.components.anchored = std::move(anchored_);
    to_.components.seedVote = std::move(seedVote_);
    to_.chunks = std::move(records_);
  }

 private:
  Accumulated& to_;
  size_t cursor_ = 0;
  std::vector<uint8_t> anchored_;
  std::vector<float> seedVote_;
  std::vector<ChunkRecord> records_;
  SpillVector<uint32_t> boundarySource_;
  UninitializedSpillVector<uint32_t> boundaryNeighbor_;
};

// Drop the points that `keep` leaves out (far outliers found earlier).
void dropExcluded(LoadedPoints& loaded, const std::vector<uint8_t>* keep) {
  if (keep == nullptr) return;
  size_t out = 0;
  for (size_t i = 0; i < loaded.source.size(); ++i) {
    if (!(*keep)[loaded.source[i]]) continue;
    loaded.source[out] = loaded.source[i];
    loaded.cloud.positions[out] = loaded.cloud.positions[i];
    if (loaded.cloud.hasNormals()) loaded.cloud.normals[out] = loaded.cloud.normals[i];
    if (loaded.cloud.hasColors()) loaded.cloud.colors[out] = loaded.cloud.colors[i];
    ++out;
  }
  loaded.source.resize(out);
  loaded.cloud.positions.resize(out);
  if (loaded.cloud.hasNormals()) loaded.cloud.normals.resize(out);
  if (loaded.cloud.hasColors()) loaded.cloud.colors.resize(out);
}

class ChunkRunner {
 public:
  ChunkRunner(const Distribution& distribution, const Frame& frame, const BuildOptions& options,
              bool inputNormals, const std::vector<uint8_t>* keep = nullptr)
      : distribution_(distribution),
        frame_(frame),
        options_(options),
        hops_(inputNormals ? 4 : 1),
        keep_(keep) {}

  // While strays are looked for in an input of one chunk (every point loaded at once): the chunk
  // stops after what finding them needs (its neighbours and their groups) and keeps its state;
  // finish() does the rest when none was found. When some were, the chunk runs again without
  // them anyway, and the normals, orientation and roughness of the first run are never made.
  void deferRest() { defer_ = true; }
  bool pending() const { return pending_ != nullptr; }
  // The i-th own point of the pending chunk (its place in the results), frame units.
  const glm::vec3& pendingPosition(size_t i) const {
    return pending_->points.position[pending_->ownBegin + i];
  }
  void finish(Accumulated& out) {
    const std::unique_ptr<Pending> p = std::move(pending_);
    const ProgressMute mute;  // the stage counted the chunk whole already
    finishChunk(*p, out);
  }
  void dropPending() { pending_.reset(); }

  void run(const SpillChunk& chunk, Accumulated& out) {
    LoadedPoints own = distribution_.load(chunk);
    dropExcluded(own, keep_);
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
      dropExcluded(halo, keep_);
      bool done = false;
      {
        const ProgressMute mute;  // the stage counts whole chunks, not its inner steps
        done = tryChunk(chunk, own, halo, lo, hi, everything, out);
      }
      if (done) {
        progressAdvance(own.source.size());
        return;
      }
      ++out.widenings;
      width *= 2.0;
    }
  }

 private:
  bool tryChunk(const SpillChunk& chunk, const LoadedPoints& own, const LoadedPoints& halo,
                const glm::dvec3& lo, const glm::dvec3& hi, bool everything, Accumulated& out) {
    PointCloud cloud = own.cloud;
    const auto append = [](auto& dst, const auto& src) {
      dst.insert(dst.end(), src.begin(), src.end());
    };
    append(cloud.positions, halo.cloud.positions);
    append(cloud.normals, halo.cloud.normals);
    append(cloud.colors, halo.cloud.colors);
    PointSet points = makePointSet(cloud, frame_);
    points.source.assign(own.source.begin(), own.source.end());
    append(points.source, halo.source);
    sortByKey(points);
    mergeDuplicates(points);
    // The chunk's own points: its Morton key range.
    const int shift = 3 * (kMaxLevel - chunk.level);
    const auto ownBegin =
        uint32_t(std::lower_bound(points.key.begin(), points.key.end(), chunk.key << shift) -
                 points.key.begin());
    const auto ownEnd =
        uint32_t(std::lower_bound(points.key.begin(), points.key.end(), (chunk.key + 1) << shift) -
                 points.key.begin());
    const PointIndex index(points.position);
    Neighbors neighbors = findNeighbors(points, index, options_.neighbors);
    if (!everything && !isExact(points, neighbors, ownBegin, ownEnd, lo, hi)) return false;
    ChunkRecord record;
    record.pointBegin = out.points.size();
    record.componentBegin = record.componentEnd = uint32_t(out.components.anchored.size());
    record.lo = lo;
    record.hi = hi;
    record.boundaryBegin = record.boundaryEnd = out.boundarySource.size();
    if (neighbors.k == 0) {  // one distinct point in the whole input: no surface (said later)
      points.roughness.assign(points.size(), 0.0f);  // as in core: no neighbours, no roughness
      appendRange(out.points, points, ownBegin, ownEnd);
      out.firstDistance.insert(out.firstDistance.end(), ownEnd - ownBegin, 0.0f);
      out.components.of.insert(out.components.of.end(), ownEnd - ownBegin, kNoNode);
      if (out.groups) out.kth.insert(out.kth.end(), ownEnd - ownBegin, 0.0f);
      record.pointEnd = out.points.size();
      out.chunks.push_back(record);
      return true;
    }

    out.maxLoaded = std::max<uint64_t>(out.maxLoaded, points.size());
    out.haloPoints += points.size() - (ownEnd - ownBegin);
    record.duplicates = own.source.size() - (ownEnd - ownBegin);
    const size_t k = size_t(neighbors.k);
    out.k = k;
    if (out.groups) {  // each own point's edges, from its exact k-NN list (specs: strays)
      const size_t before = out.edgesOut.size();
      out.groups->joinNeighbors(neighbors, ownBegin, ownEnd, uint32_t(out.points.size()),
                                out.edgesOut);
      for (size_t e = before; e < out.edgesOut.size(); ++e)
        out.edgesOut[e][1] = points.source[out.edgesOut[e][1]];
      for (uint32_t i = ownBegin; i < ownEnd; ++i)
        out.kth.push_back(neighbors.distance[size_t(i) * k + k - 1]);
    }
    auto pending = std::make_unique<Pending>(
        Pending{std::move(points), std::move(neighbors), record, ownBegin, ownEnd, chunk.level});
    if (defer_ && everything)
      pending_ = std::move(pending);
    else
      finishChunk(*pending, out);
    return true;
  }

  // A chunk's points and neighbours, between finding its strays' groups and the rest.
  struct Pending {
    PointSet points;
    Neighbors neighbors;
    ChunkRecord record;
    uint32_t ownBegin = 0, ownEnd = 0;
    uint8_t level = 0;
  };

  // Radii, normals, orientation and roughness of a chunk's own points, into the results.
  void finishChunk(Pending& chunk, Accumulated& out) {
    PointSet& points = chunk.points;
    const Neighbors& neighbors = chunk.neighbors;
    ChunkRecord& record = chunk.record;
    const uint32_t ownBegin = chunk.ownBegin, ownEnd = chunk.ownEnd;
    const size_t k = size_t(neighbors.k);
    estimateRadii(points, neighbors);
    for (uint32_t i = ownBegin; i < ownEnd; ++i)
      out.firstDistance.push_back(neighbors.distance[i * k]);
    std::vector<uint8_t> wasEstimated(points.size(), 0);
    for (size_t i = 0; i < points.size(); ++i)
      wasEstimated[i] = points.normal.empty() || points.normal[i] == glm::vec3(0.0f);
    record.normals.estimated = size_t(
        std::count(wasEstimated.begin() + ownBegin, wasEstimated.begin() + ownEnd, uint8_t{1}));
    estimateNormals(points, neighbors);
    record.normals.flipped =
        repairFlippedNormals(points, neighbors, wasEstimated, ownBegin, ownEnd);
    OrientationComponents local;
    local.of.assign(points.size(), kNoNode);
    if (options_.orient == OrientMode::Up) {
      orientUp(points, wasEstimated, ownBegin, ownEnd);
    } else {
      const OrientationBlocks blocks =
          orientationBlocks(points, options_.orientBlockPoints, ownBegin, ownEnd, chunk.level);
      local.anchored.swap(out.components.anchored);
      local.seedVote.swap(out.components.seedVote);
      propagateInBlocks(points, neighbors, wasEstimated, blocks, local);
      local.anchored.swap(out.components.anchored);
      local.seedVote.swap(out.components.seedVote);
      record.blocks = blocks.size();
    }

    // Roughness compares normals: final here for neighbours in the point's own component (whole
    // components flip together later); points with others keep their edges for later.
    points.roughness.assign(points.size(), 0.0f);
    std::vector<uint8_t> boundary(points.size(), 0);
    tbb::parallel_for(tbb::blocked_range<uint32_t>(ownBegin, ownEnd, 4096),
                      [&](const tbb::blocked_range<uint32_t>& r) {
                        for (uint32_t i = r.begin(); i < r.end(); ++i) {
                          const uint32_t* near = neighbors.index.data() + size_t(i) * k;
                          for (size_t e = 0; e < k && !boundary[i]; ++e)
                            boundary[i] = near[e] < ownBegin || near[e] >= ownEnd ||
                                          local.of[near[e]] != local.of[i];
                          if (!boundary[i]) points.roughness[i] = roughnessOf(points, i, near, k);
                        }
                      });
    for (uint32_t i = ownBegin; i < ownEnd; ++i) {
      if (!boundary[i]) continue;
      out.boundarySource.push_back(points.source[i]);
      for (size_t e = 0; e < k; ++e)
        out.boundaryNeighbor.push_back(points.source[neighbors.index[i * k + e]]);
    }
    record.boundaryEnd = out.boundarySource.size();
    appendRange(out.points, points, ownBegin, ownEnd);
    out.components.of.insert(out.components.of.end(), local.of.begin() + ownBegin,
                             local.of.begin() + ownEnd);
    record.pointEnd = out.points.size();
    record.componentEnd = uint32_t(out.components.anchored.size());
    out.chunks.push_back(record);
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
  int hops_;
  const std::vector<uint8_t>* keep_;
  bool defer_ = false;
  std::unique_ptr<Pending> pending_;
};

// After outliers were removed: the chunks whose boxes held one run again (the others would load
// the same points and give the same results) into a small set of results, then every chunk's
// results are placed in order over the old ones. Returns how many ran again.
size_t prepareTouchedAgain(const Distribution& distribution, const Frame& frame,
                           const BuildOptions& options, bool inputNormals,
                           const std::vector<uint8_t>& keep, const std::vector<glm::vec3>& strays,
                           Accumulated& done) {
  Accumulated again;
  ChunkRunner rerun(distribution, frame, options, inputNormals, &keep);
  std::vector<size_t> againOf(distribution.chunks().size(), kNoNode);
  size_t preparedAgain = 0;
  for (size_t c = 0; c < distribution.chunks().size(); ++c) {
    const ChunkRecord& record = done.chunks[c];
    const bool touched = std::any_of(strays.begin(), strays.end(), [&](const glm::vec3& u) {
      return u.x >= record.lo.x && u.y >= record.lo.y && u.z >= record.lo.z && u.x <= record.hi.x &&
             u.y <= record.hi.y && u.z <= record.hi.z;
    });
    if (touched) {
      againOf[c] = again.chunks.size();
      rerun.run(distribution.chunks()[c], again);
      ++preparedAgain;
    } else {
      progressAdvance(distribution.chunks()[c].size());
    }
  }
  const std::vector<ChunkRecord> old = done.chunks;
  InPlaceResults results(done);
  for (size_t c = 0; c < old.size(); ++c)
    if (againOf[c] == kNoNode)
      results.place(done, old[c]);
    else
      results.place(again, again.chunks[againOf[c]]);
  results.finish();
  done.haloPoints += again.haloPoints;
  done.widenings += again.widenings;
  done.maxLoaded = std::max(again.maxLoaded, done.maxLoaded);
  return preparedAgain;
}

// After outliers were removed from an input of one chunk that stopped before its normals: the
// chunk runs again, as prepareTouchedAgain would run it, into new results. Returns 1.
size_t prepareWholeAgain(const Distribution& distribution, const Frame& frame,
                         const BuildOptions& options, const PointLayout& layout,
                         const std::vector<uint8_t>& keep, Accumulated& done) {
  Accumulated again;
  reserveFor(again, distribution.size(), layout);
  ChunkRunner rerun(distribution, frame, options, layout.normals, &keep);
  rerun.run(distribution.chunks().front(), again);
  again.haloPoints += done.haloPoints;
  again.widenings += done.widenings;
  again.maxLoaded = std::max(again.maxLoaded, done.maxLoaded);
  done = std::move(again);
  return 1;
}

// The chunks' points as one set: the boundary points and their neighbours become indices into
// it, the orientation components are aligned across chunks (when `align`), and the boundary
// points' roughness, which compares normals across components, is computed after that.
void joinChunks(Accumulated& done, uint64_t rawSize, bool align) {
  PointSet& points = done.points;
  SpillVector<uint32_t> ordinal(rawSize, kNoNode);
  for (size_t i = 0; i < points.size(); ++i) ordinal[points.source[i]] = uint32_t(i);
  SpillVector<uint32_t>& from = done.boundarySource;
  UninitializedSpillVector<uint32_t>& near = done.boundaryNeighbor;
  for (uint32_t& s : from) s = ordinal[s];
  for (uint32_t& s : near) s = ordinal[s];
  ordinal = {};
  if (align) alignComponents(points.normal, done.components, from, near, done.k);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, from.size(), 1024),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t b = r.begin(); b < r.end(); ++b)
                        points.roughness[from[b]] =
                            roughnessOf(points, from[b], near.data() + b * done.k, done.k);
                    });
}

// Join the near edges between points of different chunks, now that every point has its place.
// (A neighbour merged into a duplicate has none: its survivor, the first of its copies in the
// chunk's file order, was the neighbour wherever it was loaded.)
void joinEdgesOut(Accumulated& done, uint64_t rawSize) {
  SpillVector<uint32_t> place(rawSize, kNoNode);
  for (size_t i = 0; i < done.points.size(); ++i) place[done.points.source[i]] = uint32_t(i);
  for (const auto& [from, to] : done.edgesOut)
    if (place[to] != kNoNode) done.groups->join(from, place[to]);
  SpillVector<std::array<uint32_t, 2>>().swap(done.edgesOut);
}

// ---- a distributed run's share of the chunks (Ranks)

constexpr const char* kShareFingerprint = "the point stages' results of a rank";

// Results of some chunks, with each point's group root (by place; a root is in the point's own
// chunk) when strays are looked for.
struct Share {
  Accumulated results;
  SpillVector<uint32_t> roots;
};

void takeRoots(Share& share) {
  const Accumulated& a = share.results;
  if (a.groups)
    for (size_t i = 0; i < a.points.size(); ++i) share.roots.push_back(a.groups->root(uint32_t(i)));
}

// A share's arrays of points, in their order in its file: f(name, array) for each (the points'
// columns as "points.N", like writeColumns), after the section "chunks" and before "roots".
template <typename Results, typename F>
void forEachShareArray(Results& a, F&& f) {
  int column = 0;
  PointSet::forEachColumn([&](auto& values) { f("points." + std::to_string(column++), values); },
                          a.points);
  f("first", a.firstDistance);
  f("boundary", a.boundarySource);
  f("boundary.near", a.boundaryNeighbor);
  f("of", a.components.of);
  f("anchored", a.components.anchored);
  f("votes", a.components.seedVote);
  f("kth", a.kth);
  f("edges", a.edgesOut);
}

void saveShare(const std::filesystem::path& file, const std::string& fingerprint,
               const Share& share) {
  const Accumulated& a = share.results;
  CheckpointWriter out(file, fingerprint);
  out.json(
      "counts",
      {{"k", a.k}, {"halo", a.haloPoints}, {"widenings", a.widenings}, {"loaded", a.maxLoaded}});
  out.array("chunks", a.chunks);
  forEachShareArray(a,
                    [&](const std::string& name, const auto& values) { out.array(name, values); });
  out.array("roots", share.roots);
  out.commit();
}

// The sizes of results before a share is appended to them.
struct AppendMark {
  uint32_t points, components;
  size_t firstDistance, boundary, boundaryNeighbors, of, kth, edges;
};

AppendMark markOf(const Accumulated& a) {
  return {uint32_t(a.points.size()),
          uint32_t(a.components.anchored.size()),
          a.firstDistance.size(),
          a.boundarySource.size(),
          a.boundaryNeighbor.size(),
          a.components.of.size(),
          a.kth.size(),
          a.edgesOut.size()};
}

// After a share's arrays were appended at `mark`: its indices made the results' own (its points
// and components come after those there were), its groups joined, its chunks and counts added.
void fixAppended(Accumulated& to, const AppendMark& mark, const std::span<const uint32_t> roots,
                 const std::span<const ChunkRecord> chunks, const Accumulated& counts) {
  for (size_t i = mark.of; i < to.components.of.size(); ++i)
    if (to.components.of[i] != kNoNode) to.components.of[i] += mark.components;
  for (size_t e = mark.edges; e < to.edgesOut.size(); ++e) to.edgesOut[e][0] += mark.points;
  if (to.groups)
    for (size_t i = 0; i < roots.size(); ++i)
      to.groups->join(mark.points + uint32_t(i), mark.points + roots[i]);
  for (ChunkRecord record : chunks) {
    record.pointBegin += mark.points;
    record.pointEnd += mark.points;
    record.componentBegin += mark.components;
    record.componentEnd += mark.components;
    record.boundaryBegin += mark.boundary;
    record.boundaryEnd += mark.boundary;
    to.chunks.push_back(record);
  }
  if (to.points.size() > mark.points) to.k = counts.k;
  to.haloPoints += counts.haloPoints;
  to.widenings += counts.widenings;
  to.maxLoaded = std::max(to.maxLoaded, counts.maxLoaded);
}

// Append a share's results (in chunk order after those of `to`); `to.groups`, when finding
// strays, covers every point of the distribution.
void appendShare(const Share& share, Accumulated& to) {
  const Accumulated& from = share.results;
  const AppendMark mark = markOf(to);
  appendRange(to.points, from.points, 0, uint32_t(from.points.size()));
  const auto append = [](auto& dst, const auto& src) {
    dst.insert(dst.end(), src.begin(), src.end());
  };
  append(to.firstDistance, from.firstDistance);
  append(to.boundarySource, from.boundarySource);
  append(to.boundaryNeighbor, from.boundaryNeighbor);
  append(to.components.of, from.components.of);
  append(to.components.anchored, from.components.anchored);
  append(to.components.seedVote, from.components.seedVote);
  append(to.kth, from.kth);
  append(to.edgesOut, from.edgesOut);
  fixAppended(to, mark, share.roots, from.chunks, from);
}

// Append the share a file holds, as appendShare, reading each array into its place (the file is
// read once, and its arrays are not copied again). CheckpointError when the file is not whole:
// `to` is then as it was.
void appendShareFile(const std::filesystem::path& file, const std::string& fingerprint,
                     Accumulated& to) {
  const AppendMark mark = markOf(to);
  const auto rollBack = [&] {
    PointSet::forEachColumn(
        [&](auto& column) {
          if (column.size() > mark.points) column.resize(mark.points);
        },
        to.points);
    to.firstDistance.resize(mark.firstDistance);
    to.components.of.resize(mark.of);
    to.components.anchored.resize(mark.components);
    to.components.seedVote.resize(mark.components);
    to.boundarySource.resize(mark.boundary);
    to.boundaryNeighbor.resize(mark.boundaryNeighbors);
    to.kth.resize(mark.kth);
    to.edgesOut.resize(mark.edges);
  };
  Accumulated counts;
  std::vector<ChunkRecord> chunks;
  SpillVector<uint32_t> roots;
  try {
    CheckpointReader in(file, fingerprint);
    const nlohmann::json c = in.json("counts");
    counts.k = c["k"];
    counts.haloPoints = c["halo"];
    counts.widenings = c["widenings"];
    counts.maxLoaded = c["loaded"];
    in.array("chunks", chunks);
    forEachShareArray(to,
                      [&](const std::string& name, auto& values) { in.appendArray(name, values); });
    in.array("roots", roots);
    in.finish();
  } catch (const CheckpointError&) {
    rollBack();
    throw;
  }
  fixAppended(to, mark, roots, chunks, counts);
}

// Results of `points` points to come, as one process would hold them.
Accumulated resultsFor(uint64_t points, const PointLayout& layout, bool findingOutliers) {
  Accumulated a;
  reserveFor(a, points, layout);
  if (findingOutliers) a.groups = std::make_unique<PointGroups>(points);
  return a;
}

// A resumable run's chunks (ResumeState): each chunk's results are a checkpoint of their own
// ("chunk-P-C", P the pass: strays that change the frame make a second), so that a run killed in
// the point stages keeps the chunks it finished. Returns how many it kept.
size_t runResumable(const Distribution& distribution, ChunkRunner& runner, ResumeState& resume,
                    int pass, const PointLayout& layout, bool findingOutliers, Accumulated& done) {
  size_t kept = 0;
  const std::string fingerprint = resume.fingerprint() + " pass " + std::to_string(pass);
  for (size_t c = 0; c < distribution.chunks().size(); ++c) {
    const SpillChunk& chunk = distribution.chunks()[c];
    const std::string name = "chunk-" + std::to_string(pass) + "-" + std::to_string(c);
    if (resume.has(name)) try {
        appendShareFile(resume.path(name), fingerprint, done);
        progressAdvance(chunk.size());
        ++kept;
        continue;
      } catch (const CheckpointError& e) {
        resume.discard(name, e.what());
      }
    Share share{resultsFor(chunk.size(), layout, findingOutliers), {}};
    runner.run(chunk, share.results);
    takeRoots(share);
    saveShare(resume.path(name), fingerprint, share);
    appendShare(share, done);
  }
  return kept;
}

// The ranks claim the chunks in order as they become free (claimFile in the shared directory) and
// run them; rank 0 appends every chunk's results to `done` in chunk order: its own as it runs them
// (or, run before their turn, once it comes), the others' from their files in the shared
// directory as they come. The ranks' loads balance, and rank 0 appends while the others run.
void runShare(const Distribution& distribution, ChunkRunner& runner, const Ranks& ranks, int pass,
              const PointLayout& layout, bool findingOutliers, Accumulated& done) {
  const std::vector<SpillChunk>& chunks = distribution.chunks();
  const auto file = [&](const char* what, size_t c) {
    return ranks.shared /
           (std::string(what) + "-" + std::to_string(pass) + "-" + std::to_string(c));
  };
  const auto runApart = [&](size_t c) {
    Share share{resultsFor(chunks[c].size(), layout, findingOutliers), {}};
    runner.run(chunks[c], share.results);
    takeRoots(share);
    return share;
  };
  if (ranks.rank != 0) {
    for (size_t c = 0; c < chunks.size(); ++c)
      if (claimFile(file("claim", c))) saveShare(file("points", c), kShareFingerprint, runApart(c));
    ranks.barrier();
    return;
  }
  std::map<size_t, Share> ahead;  // rank 0's, run before their turn
  size_t claimFrom = 0;
  for (size_t next = 0; next < chunks.size();) {
    if (const auto own = ahead.find(next); own != ahead.end()) {
      appendShare(own->second, done);
      ahead.erase(own);
      ++next;
      continue;
    }
    if (const std::filesystem::path theirs = file("points", next);
        std::filesystem::exists(theirs)) {
      try {
        appendShareFile(theirs, kShareFingerprint, done);
      } catch (const CheckpointError& e) {
        throw std::runtime_error(std::string("a rank's results cannot be read: ") + e.what());
      }
      std::filesystem::remove(theirs);
      progressAdvance(chunks[next].size());
      ++next;
      continue;
    }
    while (claimFrom < chunks.size() && !claimFile(file("claim", claimFrom))) ++claimFrom;
    if (claimFrom < chunks.size()) {
      if (claimFrom == next)
        runner.run(chunks[next++], done);
      else
        ahead.emplace(claimFrom, runApart(claimFrom));
      ++claimFrom;
      continue;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // `next` is another rank's
  }
  ranks.barrier();
  for (size_t c = 0; c < chunks.size(); ++c) std::filesystem::remove(file("claim", c));
}

// Rank 0's word to the others once it has judged the strays: empty when they are done, else the
// new frame and which input points to keep, for running every chunk again.
std::vector<std::byte> againMessage(const Frame& frame, const std::vector<uint8_t>& keep) {
  std::vector<std::byte> message(sizeof(Frame) + keep.size());
  std::memcpy(message.data(), &frame, sizeof(Frame));
  std::memcpy(message.data() + sizeof(Frame), keep.data(), keep.size());
  return message;
}

// Every k-th kept input point (world units), for the accuracy measure, as in core.
std::vector<glm::dvec3> accuracySample(const RawSpill& raw, const std::vector<uint8_t>& keep) {
  size_t kept = 0;
  for (uint64_t i = 0; i < raw.size(); ++i) kept += keep.empty() || keep[i] ? 1 : 0;
  const size_t step = sampleStep(kept, kAccuracySamples);
  std::vector<glm::dvec3> sample;
  size_t ordinalKept = 0;
  raw.forEachBatch([&](const PointCloud& batch, uint64_t first) {
    for (size_t i = 0; i < batch.size(); ++i) {
      if (!keep.empty() && !keep[first + i]) continue;
      if (ordinalKept++ % step == 0) sample.push_back(batch.positions[i]);
    }
  });
  return sample;
}

}  // namespace

ReadyPoints prepareOutOfCore(const RawSpill& raw, SpillDirectory& directory,
                             const BuildOptions& options, uint64_t maxChunkPoints,
                             const std::function<void(const std::string&, uint64_t)>& stage,
                             bool collectStrays, const Ranks* ranks, ResumeState* resume) {
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
  size_t chunks = 0, preparedAgain = 0;
  const bool shared = ranks != nullptr && ranks->count > 1;
  int pass = 0;        // of the chunks: a second when strays change the frame
  size_t resumed = 0;  // chunks whose results a resumable run kept
  const bool worker = shared && ranks->rank != 0;
  // Rank 0's word to the others once it has judged the strays (againMessage).
  const auto tell = [&](std::vector<std::byte> word) {
    if (shared) ranks->broadcast(word);
  };
  for (;;) {
    stage("distribute", 2 * raw.size());
    const Distribution distribution(directory, raw, ready.frame, maxChunkPoints,
                                    keep.empty() ? nullptr : &keep);
    peakTemporary = std::max(peakTemporary, directory.bytes());
    chunks = distribution.chunks().size();
    stage("points", distribution.size());
    done = Accumulated{};
    if (!worker) reserveFor(done, distribution.size(), raw.layout());
    if (findingOutliers && !worker)
      done.groups = std::make_unique<PointGroups>(distribution.size());
    ChunkRunner runner(distribution, ready.frame, options, raw.layout().normals);
    const bool one = distribution.chunks().size() == 1;  // rank 0 runs it alone
    if (findingOutliers && one) runner.deferRest();
    if (shared && !one)
      runShare(distribution, runner, *ranks, pass, raw.layout(), findingOutliers, done);
    else if (resume != nullptr && !one)
      resumed +=
          runResumable(distribution, runner, *resume, pass, raw.layout(), findingOutliers, done);
    else if (!worker)
      for (const SpillChunk& chunk : distribution.chunks()) runner.run(chunk, done);
    ++pass;
    if (!findingOutliers) break;
    findingOutliers = false;
    if (worker) {
      std::vector<std::byte> word;
      ranks->broadcast(word);
      if (word.empty()) break;
      std::memcpy(&ready.frame, word.data(), sizeof(Frame));
      keep.assign(word.size() - sizeof(Frame), 0);
      std::memcpy(keep.data(), word.data() + sizeof(Frame), keep.size());
      continue;
    }
    joinEdgesOut(done, raw.size());
    const Strays found = flagStrays(done.kth, *done.groups, options.strayGroupPoints);
    done.groups.reset();
    done.kth = {};
    if (found.sparse + found.grouped == 0) {
      tell({});
      if (runner.pending()) runner.finish(done);
      break;
    }
    // Without the strays the points are prepared again, as in core: with a new frame when they
    // held the bounds (far strays waste its precision), else only the chunks whose boxes held
    // one (the others would load the same points and give the same results).
    StrayPositions positions;
    const bool stoppedEarly = runner.pending();  // the one chunk, which holds them all
    for (size_t i = 0; i < found.flagged.size(); ++i)
      if (found.flagged[i])
        positions.add(stoppedEarly ? runner.pendingPosition(i) : done.points.position[i]);
    runner.dropPending();
    positions.seal();
    keep.assign(raw.size(), 1);
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    std::vector<glm::vec3> strays;
    raw.forEachBatch([&](const PointCloud& batch, uint64_t first) {
      for (size_t i = 0; i < batch.size(); ++i) {
        const glm::vec3 p(toFrame(batch.positions[i], ready.frame));
        if (positions.contains(p)) {
          keep[first + i] = 0;
          strays.push_back(p);
          if (collectStrays) appendPoint(ready.strays, batch, i);
          continue;
        }
        lo = glm::min(lo, batch.positions[i]);
        hi = glm::max(hi, batch.positions[i]);
      }
    });
    ready.outliers = {strays.size(), found.sparse, found.grouped};
    const Frame frame = chooseFrame(lo, hi);
    if (frame.origin != ready.frame.origin || frame.size != ready.frame.size) {
      ready.frame = frame;
      tell(againMessage(frame, keep));
      continue;
    }
    tell({});                                    // the chunks that held strays run here alone
    stage("points again", distribution.size());  // the chunks that held strays, without them
    preparedAgain = stoppedEarly ? prepareWholeAgain(distribution, ready.frame, options,
                                                     raw.layout(), keep, done)
                                 : prepareTouchedAgain(distribution, ready.frame, options,
                                                       raw.layout().normals, keep, strays, done);
    break;
  }
  if (worker) return {};
  size_t blocks = 0;
  for (const ChunkRecord& record : done.chunks) {
    blocks += record.blocks;
    ready.duplicates += record.duplicates;
    ready.normals.estimated += record.normals.estimated;
    ready.normals.flipped += record.normals.flipped;
  }

  stage("orient", done.points.size());
  PointSet& points = done.points;
  const size_t n = points.size();
  joinChunks(done, raw.size(),
             options.orient != OrientMode::Up && blocks > 1 && ready.normals.estimated > 0);
  progressAdvance(n);

  ready.radii.spacing = medianOf(done.firstDistance);  // reorders: not needed after this
  SpillVector<float> radii = points.radius;
  ready.radii.medianRadius = medianOf(radii);
  ready.points = std::move(points);

  ready.sample = accuracySample(raw, keep);
  ready.outOfCore = {{"chunks", chunks},
                     {"max_chunk_points", maxChunkPoints},
                     {"largest_loaded_points", done.maxLoaded},
                     {"halo_points", done.haloPoints},
                     {"halo_widenings", done.widenings},
                     {"boundary_points", done.boundarySource.size()},
                     {"chunks_prepared_again", preparedAgain},
                     {"ranks", shared ? ranks->count : 1},
                     {"chunks_resumed", resumed},
                     {"temporary_bytes_peak", peakTemporary}};
  return ready;
}

void writeColumns(CheckpointWriter& out, const PointSet& points) {
  int column = 0;
  PointSet::forEachColumn(
      [&](const auto& values) { out.array("points." + std::to_string(column++), values); }, points);
}

void readColumns(CheckpointReader& in, PointSet& points) {
  int column = 0;
  PointSet::forEachColumn(
      [&](auto& values) { in.array("points." + std::to_string(column++), values); }, points);
}

}  // namespace iso
