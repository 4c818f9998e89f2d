// The original points kept in the .iso file (`iso convert --keep-points`): Draco-compressed points
// chunks, one octree cell each (specs/iso-format.md, "Points chunks"; specs/pipeline.md §17).
#pragma once

#include <cstdint>
#include <functional>
#include <glm/vec3.hpp>
#include <limits>
#include <memory>
#include <string>
#include <nlohmann/json.hpp>
#include <vector>

#include "iso/format.h"
#include "iso/points.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

class Writer;
class Reader;
class RawSpill;
class SpillDirectory;
struct PointSet;

// Points per chunk the writer aims at (fewer where a cell holds fewer; a cell of the finest grid
// holding more is split into several chunks of that cell).
inline constexpr uint32_t kPointsPerChunk = uint32_t{1} << 16;

// What a PointsChunkWriter writes besides the points: a values chunk for every points chunk
// (specs/iso-format.md, "Values chunks"), and which kind of points.
struct KeptValues {
  std::string name;     // the values' name; empty: no values chunks
  bool density = false;  // the values are the local point density: k / (π r²), in points per
                         // square world unit, from the radius r each point gets (k: neighbours)
  int neighbours = 10;
};

struct KeptPointsStats {
  uint64_t chunks = 0, points = 0, bytes = 0;  // bytes: the chunks' data (subsamples included)
  uint64_t valuesChunks = 0, valuesBytes = 0;  // values chunks (subsamples' included)
  std::string valuesName;
  uint64_t subsampleChunks = 0, subsamplePoints = 0;  // the subsample chunks (not in `chunks`)
  uint64_t radiiFromConversion = 0;  // points whose radius and normal are a prepared point's
  int stepBits = 0;                            // asked for
  uint64_t coarserChunks =
      0;                  // chunks whose offsets needed a coarser step (points outside the frame)
  double maxError = 0.0;  // largest distance of a stored point from its input, world units
  nlohmann::json json() const;
};

// Cuts points, given in Morton order (key at kMaxLevel, then input index), into cells and writes
// each as a points chunk. Every decision depends only on the points, so any way of producing the
// same sequence (in core, or out of core chunk by chunk) writes the same bytes. A cell becomes a
// chunk when it is the coarsest one that holds the next point, starts after the previous chunk and
// holds at most `perChunk` points; a cell of the header's maxLevel holding more is split into
// chunks of `perChunk` points in order. Points outside the frame's cube (far outliers the
// conversion removed) come last, in chunks of the root cell of their own. Chunks are encoded in
// parallel, a batch at a time.
//
// Every point gets a splat radius: the k-NN radius of the conversion's point at its position
// (`prepared`, sorted by key as the points come), else the radius of the point before it, else one
// from its chunk's density. Points without an input normal take that prepared point's normal.
// Subsample chunks are written as the Morton order leaves cells: every chunk gives every 8th of its
// points (radius × √8) to the cell one level up; a cell that got them from two or more chunks
// becomes a subsample chunk, the parent of those chunks, and gives on in turn; one that got them
// from one chunk passes them on unchanged (specs/iso-format.md, "Points chunks").
class PointsChunkWriter {
 public:
  // `volume`: volume points chunks (specs/iso-format.md, "Volume points"): no radii, no
  // subsamples.
  PointsChunkWriter(Writer& writer, const FileHeader& header, int stepBits, bool colors,
                    bool normals, uint32_t perChunk = kPointsPerChunk,
                    const PointSet* prepared = nullptr, KeptValues values = {},
                    bool volume = false);
  ~PointsChunkWriter();
  // One point: world position, its key (keyOf of its frame position), normal, linear color and
  // value (each ignored unless the writer keeps it; a NaN value: none).
  void push(const glm::dvec3& world, uint64_t key, const glm::vec3& normal, const glm::vec3& color,
            double value = std::numeric_limits<double>::quiet_NaN());
  // Write what is left.
  void finish();
  const KeptPointsStats& stats() const { return stats_; }

 private:
  struct Point {
    uint64_t key;
    glm::dvec3 world;
    glm::vec3 normal, color;
    float radius;  // frame units; 0: not known (from the chunk's density)
    double value;
  };
  struct Pending {
    uint8_t level;
    uint64_t key;
    std::vector<Point> points;
    uint64_t sequence = 0;             // the chunk's place in the order of writing
    std::vector<uint64_t> children;    // a subsample's: the chunks it is the parent of
  };
  // A cell collecting the subsamples of the chunks inside it (Morton order: at most one per level
  // is open at a time, nested).
  struct Gathering {
    uint8_t level;
    uint64_t cell;
    std::vector<Point> points;
    std::vector<uint64_t> chunks;  // the chunks (sequences) whose subsamples are here
    int gifts = 0;                 // subsamples given (a passed-on one counts as one)
  };
  void cutOne();
  void flush();
  void queue(Pending chunk);
  // Close the gatherings that do not contain the cell (level, cell), innermost first (all with
  // level 255).
  void closeGatherings(uint8_t level, uint64_t cell);
  // Give every 8th of the points (radius × √8) to the gathering of the cell one level above
  // (level, cell), as the chunks `from`.
  void give(uint8_t level, uint64_t cell, const std::vector<Point>& points,
            std::vector<uint64_t> from, bool thinOut);
  float preparedMatch(uint64_t key, const glm::dvec3& world, glm::vec3& normal);

  Writer& writer_;
  Frame frame_;
  uint8_t finest_;  // the deepest level a chunk may have
  int stepBits_;
  bool colors_, normals_;
  uint32_t perChunk_;
  std::vector<Point> buffer_;
  size_t head_ = 0;
  std::vector<Point> outside_;  // points outside the frame's cube
  uint64_t floor_ = 0;          // keys below belong to chunks already cut
  bool continues_ = false;      // the last chunk cut a finest cell that goes on
  std::vector<Pending> pending_;
  std::vector<Gathering> gatherings_;  // open, coarsest first
  uint64_t sequence_ = 0;               // chunks queued so far
  std::vector<uint32_t> idOf_;          // the chunk id of each sequence written
  const PointSet* prepared_;
  KeptValues values_;
  bool volume_;
  size_t cursor_ = 0;       // in prepared_'s keys
  float lastRadius_ = 0.0f;  // the radius of the last point pushed inside the frame
  KeptPointsStats stats_;
};

// The points of a cloud (in core), in Morton order, in the header's frame and levels.
// Values (KeptValues::name, unless density) are the cloud's one extra; volume: as volume points.
KeptPointsStats keepPoints(Writer& writer, const PointCloud& cloud, const FileHeader& header,
                           int stepBits, uint32_t perChunk = kPointsPerChunk,
                           const PointSet* prepared = nullptr, const KeptValues& values = {},
                           bool volume = false);
// The points of a raw spill (out of core), counting-sorted by cell through a Distribution of at
// most maxLoadedPoints points at a time; the same bytes as keepPoints on the same points.
KeptPointsStats keepPoints(Writer& writer, const RawSpill& raw, SpillDirectory& directory,
                           const FileHeader& header, int stepBits, uint64_t maxLoadedPoints,
                           uint32_t perChunk = kPointsPerChunk, const PointSet* prepared = nullptr,
                           const KeptValues& values = {});

// Points chunk `id` of a file (or volume points chunk), decoded: world positions, unit normals and
// linear colors (when kept) and, given its values chunk (valuesChunks), the values as the one
// extra (NaN: none).
PointCloud decodeKeptPoints(const Reader& reader, uint32_t id, uint32_t valuesChunk = kNoParent);

// The values chunks of a file's points chunks: per chunk id, the values chunk of that name of
// the points chunk of this id, or kNoParent. Decodes (and checks) every values chunk.
std::vector<uint32_t> valuesChunks(const Reader& reader, const std::string& name);
// The names of the values the file keeps for its points chunks of `kind` (kPointsKind or
// kVolumePointsKind), in the order first met.
std::vector<std::string> keptValueNames(const Reader& reader, uint8_t kind = kPointsKind);

// The points chunks to draw at most maxPoints points (a level of detail under a memory budget):
// from the coarsest, a subsample chunk gives way to the chunks it thins out, coarser chunks
// first, while the sum of the chunks' points stays within maxPoints; the roots when even they
// do not fit. Chunk ids in file order.
std::vector<uint32_t> keptPointsCut(const Reader& reader, uint64_t maxPoints);

// Every points chunk of a file but its subsamples, decoded, in file order: world positions, unit normals and linear
// colors (when kept). Calls f once per chunk.
// With `values`, each point carries the value of that name as its one extra; `kind`:
// kVolumePointsKind gives the volume points instead.
void forEachKeptPoints(const Reader& reader,
                       const std::function<void(const PointCloud& points)>& f,
                       const std::string& values = "", uint8_t kind = kPointsKind);
// Points the file keeps (the sum of its points chunks' counts) and whether they have colors and
// normals.
struct KeptPointsInfo {
  uint64_t points = 0, chunks = 0;
  bool colors = false, normals = false;
};
KeptPointsInfo keptPointsInfo(const Reader& reader, uint8_t kind = kPointsKind);

}  // namespace iso
