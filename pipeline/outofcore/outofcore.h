// The point stages of a conversion (frame, sort, duplicates, outliers, radii, normals,
// orientation) run in core on one cloud, or out of core chunk by chunk with halos over a
// Distribution; both give the same points, bit for bit (specs/pipeline.md, "Out of core").
#pragma once

#include <cstdint>
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

// Points ready for the octree stages.
struct ReadyPoints {
  Frame frame;
  PointSet points;                    // sorted by key, merged, with radii, normals, roughness
  std::unique_ptr<PointIndex> index;  // over points.position
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

// Every point of `raw` (minus far outliers) prepared chunk by chunk: chunks of at most
// maxChunkPoints points (at least options.orientBlockPoints) are loaded with a halo wide enough
// that every neighbourhood a chunk's points need lies inside it (checked; widened when not).
// `stage` is called as each phase begins, with its name and amount of work. With collectStrays
// the removed input points are kept in ReadyPoints::strays.
ReadyPoints prepareOutOfCore(const RawSpill& raw, SpillDirectory& directory,
                             const BuildOptions& options, uint64_t maxChunkPoints,
                             const std::function<void(const std::string&, uint64_t)>& stage,
                             bool collectStrays = false);

// Input points sampled for the accuracy measure: every ceil(n / kAccuracySamples)-th.
inline constexpr size_t kAccuracySamples = 100000;
inline size_t sampleStep(size_t n, size_t limit) {
  return std::max<size_t>(1, (n + limit - 1) / std::max<size_t>(limit, 1));
}

}  // namespace iso
