// The point stages of a conversion (frame, sort, duplicates, outliers, radii, normals,
// orientation) run in core on one cloud, or out of core chunk by chunk with halos over a
// Distribution; both give the same points, bit for bit (specs/pipeline.md, "Out of core").
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "pipeline/base/options.h"
#include "pipeline/outofcore/spill.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {

class CheckpointReader;
class CheckpointWriter;
class ResumeState;

// Points ready for the octree stages.
struct ReadyPoints {
  Frame frame;
  PointSet points;                    // sorted by key, merged, with radii, normals, roughness
  std::unique_ptr<PointIndex> index;  // over points.position; null where not yet built
  RadiusStats radii;
  NormalStats normals;
  size_t duplicates = 0;  // input points merged into others
  struct {
    size_t removed = 0;  // input points removed as strays (duplicates included)
    size_t sparse = 0;   // prepared points in groups far sparser than the scan
    size_t grouped = 0;  // prepared points in small groups
  } outliers;
  PointCloud strays;                   // the removed input points (world units), when asked for
  std::vector<glm::dvec3> sample;      // input points for the accuracy measure (world units)
  nlohmann::json outOfCore = nullptr;  // chunks, halos, temporary bytes (streamed only)
};

// The ranks of a distributed run (`mpirun -np N iso convert`; the engine's calls are in
// tools/iso/ranks.cpp). Each rank claims the point stages' chunks in chunk order as it becomes
// free (a file made with O_EXCL in `shared`) and runs them; the others leave each chunk's results
// in `shared`, which rank 0 appends to its own in chunk order as they come, so that the results
// are those of one process. Rank 0 alone judges the strays (the others run the chunks again when
// they change the frame) and goes on to the octree stages.
struct Ranks {
  int rank = 0, count = 1;
  std::filesystem::path shared;  // a directory every rank sees
  std::function<void()> barrier;
  // Rank 0's bytes to every rank (resized on the others).
  std::function<void(std::vector<std::byte>&)> broadcast;
};

// Every point of `raw` (minus far outliers) prepared chunk by chunk: chunks of at most
// maxChunkPoints points (at least options.orientBlockPoints) are loaded with a halo wide enough
// that every neighbourhood a chunk's points need lies inside it (checked; widened when not).
// `stage` is called as each phase begins, with its name and amount of work. With collectStrays
// the removed input points are kept in ReadyPoints::strays. With `ranks`, each rank calls it
// with the same arguments; on ranks other than 0 it returns empty points once rank 0 needs them no
// more. With `resume`, each chunk's results are kept in it as they are made (chunk-P-C), and a
// chunk whose results are there whole is not run again.
ReadyPoints prepareOutOfCore(const RawSpill& raw, SpillDirectory& directory,
                             const BuildOptions& options, uint64_t maxChunkPoints,
                             const std::function<void(const std::string&, uint64_t)>& stage,
                             bool collectStrays = false, const Ranks* ranks = nullptr,
                             ResumeState* resume = nullptr);

// Every column of a point set as a checkpoint's sections, in PointSet::forEachColumn's order.
void writeColumns(CheckpointWriter& out, const PointSet& points);
void readColumns(CheckpointReader& in, PointSet& points);

// Input points sampled for the accuracy measure: every ceil(n / kAccuracySamples)-th.
inline constexpr size_t kAccuracySamples = 100000;
inline size_t sampleStep(size_t n, size_t limit) {
  return std::max<size_t>(1, (n + limit - 1) / std::max<size_t>(limit, 1));
}

}  // namespace iso
