// The two checkpoints of a resumable conversion (`iso convert --resume`, specs/pipeline.md §15):
// the prepared points when the point stages end, and the tree with its corner field when the
// octree stages before the level of detail end. Each holds everything the stages after it read,
// so that a conversion resumed from it writes the same bytes as one that ran through.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "pipeline/base/checkpoint.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/outofcore/outofcore.h"

namespace iso {

inline constexpr const char* kPointsCheckpoint = "points.checkpoint";
inline constexpr const char* kCornersCheckpoint = "corners.checkpoint";

// What the octree stages before the level of detail leave: the tree, its closed and fitted corner
// field, and their counts for the report.
struct CornerStageResults {
  Octree octree;
  Closure closure;
  OctreeStats stats;
  size_t passive = 0, splits = 0, trimmed = 0;
  // Chunk jobs: the level-of-detail corners they could evaluate (sampleLodCornersWithin), in
  // chunk order.
  SpillVector<LodSample> lod;
};

// Write the prepared points (without their index, which is made again from them).
void savePoints(const ResumeState& state, const ReadyPoints& ready);
// The prepared points of the checkpoint with their index, or nullopt (with a note in `state`) when
// there is none or it cannot be used.
std::optional<ReadyPoints> loadPoints(ResumeState& state);

// The corner stage's results under `name`: kCornersCheckpoint for the whole run, or a chunk job's
// (octreeChunkCheckpoint).
void saveCornerStage(const ResumeState& state, const CornerStageResults& results,
                     const std::string& name = kCornersCheckpoint);
std::optional<CornerStageResults> loadCornerStage(ResumeState& state,
                                                  const std::string& name = kCornersCheckpoint);
// A finished chunk job of the octree stages (pipeline/convert/corner_stages.h), kept until the
// corners' checkpoint holds them all.
inline constexpr const char* kOctreeChunkPrefix = "octree-chunk-";
inline std::string octreeChunkCheckpoint(size_t chunk) {
  return kOctreeChunkPrefix + std::to_string(chunk);
}

}  // namespace iso
