// The octree stages before the level of detail (octree, passive leaves, balance, the corners closed
// and fitted, trimming): one run over all points, or independent chunk jobs, each over an owned
// Morton range of cells and a halo of whole cells around it, whose owned parts are merged into one
// tree and one corner field (specs/pipeline.md §15, "Chunk runs of the octree stages").
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "pipeline/base/options.h"
#include "pipeline/convert/checkpoints.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/outofcore/outofcore.h"
#include "pipeline/points/points.h"

namespace iso {

// Seconds spent in each part of the stages (summed over chunk jobs).
struct CornerStageSeconds {
  double load = 0.0, octree = 0.0, passiveBalance = 0.0, corners = 0.0, lod = 0.0, merge = 0.0;
  double ranks = 0.0;  // rank 0 waiting for the other ranks' chunks
};

// The stages over these points in one run; `stage` is called with "octree", "passive+balance" and
// "corners" as each begins. Passive leaves are marked at levels >= minPassiveLevel only (0: at
// every level).
CornerStageResults runCornerStages(PointSet& points, const SdfEvaluator& sdf,
                                   const BuildOptions& options, const RadiusStats& radii,
                                   uint8_t minPassiveLevel,
                                   const std::function<void(const char*)>& stage);

// The partition of a chunked run: chunk c owns the cells of level cellLevel whose keys lie in
// [firstCell[c], firstCell[c + 1]) (the last one up to 8^cellLevel), so the chunks cover the
// frame; its halo is every cell of level haloLevel (the coarsest tested level, two below
// cellLevel) with points that touches (by a face, an edge or a corner) a cell of that level it
// owns. A function of the points and the options only.
struct OctreeChunkPlan {
  uint8_t cellLevel = 0, haloLevel = 0;
  std::vector<uint64_t> firstCell;   // one a chunk
  std::vector<uint32_t> firstPoint;  // one a chunk, then the number of points
  LodProxyLevels lodProxyLevels{};   // of all points: what the jobs' level of detail reads
  size_t chunks() const { return firstCell.size(); }
  CellCut cut() const { return {cellLevel, firstCell}; }
};
// One chunk when the points are at most options.octreeChunkPoints or the tree is too shallow to
// cut; else Morton ranges of cells of about that many points each.
OctreeChunkPlan planOctreeChunks(const PointSet& points, const RadiusStats& radii,
                                 const BuildOptions& options);

struct ChunkRunStats {
  uint64_t haloPoints = 0;  // points loaded beside the owned ones, over all chunks
  size_t resumed = 0;       // chunks taken from their checkpoints
  size_t seamSplits = 0;    // leaves the merge split for balance where two chunks met
  size_t seamFills = 0;     // empty cells the merge filled where the surface ran across a seam
};
// The stages as chunk jobs, one after the other (each parallel inside), then the merge: the owned
// nodes of each chunk become the tree below the cells of the plan's level, corners are taken from
// the chunk that made them first (chunk order), the jobs' level-of-detail corners are kept in the
// results (CornerStageResults::lod: the corners of owned nodes finer than the halo's cells whose
// evaluation reads only points within a halo cell's width, as sampleLodCorners over all points
// would evaluate them), filled leaves that two chunks left more than one
// level apart are balanced and the surface is closed from the leaves along the seams (new leaves'
// corners from `sdf`, the signed distance over all points), and hanging corners are found and
// snapped again over the whole tree. `onChunk` is called with the chunk's own points as each
// chunk ends (the jobs' inner stages count no progress). With `resume`, each chunk's results are
// kept in it as it ends (octreeChunkCheckpoint), and a chunk whose results are there whole is not
// run again. With `ranks` (rank 0 of several), the chunks are shared: see runCornerStagesAsRank.
CornerStageResults runCornerStagesByChunk(const PointSet& points, const OctreeChunkPlan& plan,
                                          const SdfEvaluator& sdf, const BuildOptions& options,
                                          const RadiusStats& radii, CornerStageSeconds& seconds,
                                          ChunkRunStats& stats,
                                          const std::function<void(uint64_t)>& onChunk = {},
                                          ResumeState* resume = nullptr,
                                          const Ranks* ranks = nullptr);

// The chunk jobs shared by the ranks of a distributed run (specs/pipeline.md §15, "Ranks"). Rank 0
// tells the others, once its point stages are done, whether the octree stages run as chunk jobs:
// it calls tellRanks with the points (nothing when they run in one), which keeps them in its
// shared directory, and then runCornerStagesByChunk with `ranks`. Every other rank calls
// runCornerStagesAsRank after its point stages: it reads the points and makes the same plan. Every
// rank then claims the chunks in chunk order as it becomes free (a file made with O_EXCL in the
// shared directory: each chunk runs once), and the others keep their results there. Rank 0 merges
// in chunk order as results come, its own and the others', so it runs fewer chunks itself.
void tellRanks(const Ranks& ranks, const PointSet* points, const RadiusStats& radii);
void runCornerStagesAsRank(const BuildOptions& options, const Ranks& ranks);

}  // namespace iso
