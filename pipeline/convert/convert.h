// Points to an .iso file: the conversion driver over the stages of points/, octree/ and output/,
// in core or out of core, with its report (per-stage time, points/s, memory, octree shape, sizes,
// accuracy, visibility).
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

#include "iso/error.h"
#include "pipeline/base/options.h"
#include "pipeline/base/progress.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

class ResumeState;
struct Ranks;

// Input that does not define a surface (no points, fewer than 3 distinct ones, all on a line).
class ConvertError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Where the points came from, for the report and the file's metadata.
struct ConvertSource {
  // e.g. [{"file": ..., "format": ..., "points": ..., "crs": {...}}]; "crs" (the input's
  // coordinate system: "wkt", "epsg", "vertical_epsg", "name", "source") only where it has one.
  nlohmann::json inputs = nlohmann::json::array();
  double readSeconds = 0.0;       // reported as the "read" stage
  uint64_t nonFiniteDropped = 0;  // points the readers dropped
  // Called when a stage ends, with its name and duration.
  std::function<void(const std::string& stage, double seconds)> onStage;
  ProgressReporter* progress = nullptr;  // shows each stage's progress when set
  // When set, called once with the input points removed as strays (world units, their normals
  // and colors), before the octree stages.
  std::function<void(PointCloud strays)> onStrays;
  // Samples of a volume inside the scanned surface, with their one extra (the values named by
  // BuildOptions::keepScalar): written as volume points chunks with their values, never used to
  // build the surface (specs/iso-format.md, "Volume points").
  const PointCloud* volumePoints = nullptr;
  // When set (`iso convert --resume`): the conversion goes on from the last checkpoint of this
  // state that it finds whole, and writes a checkpoint as the point stages and as the octree
  // stages before the level of detail end (pipeline/convert/checkpoints.h). The report says what
  // it resumed from under "resumed".
  ResumeState* resume = nullptr;
  // When set, this is rank 0 of a distributed run: the point stages are shared with the other
  // ranks, which call prepareAsRank (pipeline/outofcore/outofcore.h, Ranks).
  const Ranks* ranks = nullptr;
};

// The coordinate system of a conversion's inputs (ConvertSource::inputs): the first input's that
// has one, with "input" (its file) added and, when other inputs declare a different one,
// "differing_inputs" (their files; each input's own is in its entry). Null when no input has one.
nlohmann::json coordinateSystemOf(const nlohmann::json& inputs);

// Convert the points into the .iso file at output (written atomically). Returns the report. The
// file's metadata holds it under "report" (with "inputs", "parameters", "generator" and, when an
// input declares one, "crs": coordinateSystemOf(inputs)) without the parts that vary from run to
// run (stage times, points/s, peak memory): the output bytes depend only on the input and the
// options.
nlohmann::json convertToIso(const PointCloud& cloud, const std::filesystem::path& output,
                            const BuildOptions& options, const ConvertSource& source = {});

class RawSpill;
class SpillDirectory;
// How an out-of-core conversion uses memory (specs/pipeline.md §15).
struct OutOfCoreBudget {
  uint64_t maxChunkPoints = 1u << 20;  // points per chunk of the point stages (with halos)
  // Resident bytes the process is kept near by dropping spilled arrays' pages (SpillArea); 0:
  // no array is spilled.
  uint64_t memory = 0;
  uint64_t minSpilledBytes = uint64_t{2} << 20;  // smaller arrays stay in memory
  // The budget for `--memory`: chunks of memory / 600 points (the point stages hold about 600
  // bytes per loaded point: positions, attributes, neighbours, their graph, chunk and halo
  // together), and every per-point array of memory / 32 or more spilled.
  static OutOfCoreBudget forMemory(uint64_t memory);
  // The smallest budget a conversion keeps to, its peak memory within the budget + 10 % (measured
  // with the default orientation blocks and octree chunk jobs: specs/pipeline.md §15). Below it,
  // what does not shrink with the budget takes more: the process itself (about 150 MiB), a chunk
  // of the point stages (an orientation block at least) and a chunk job of the octree stages.
  static constexpr uint64_t kSmallestMemory = uint64_t{512} << 20;
};
// The same for points streamed to disk (pipeline/outofcore/spill.h): the point stages run chunk by
// chunk, chunks of at most budget.maxChunkPoints points with their halos, and the prepared points
// (and their index) live in spilled arrays that the octree stages read in Morton order (the output
// is the same as convertToIso's for the same points); the report adds "out_of_core" (chunks, halos,
// temporary and spilled bytes). With budget.memory set, one such conversion runs at a time in a
// process (the spill area and its pager are the process's).
nlohmann::json convertSpilled(const RawSpill& raw, SpillDirectory& directory,
                              const OutOfCoreBudget& budget, const std::filesystem::path& output,
                              const BuildOptions& options, const ConvertSource& source = {});
// A rank other than 0 of a distributed run: its share of the point stages, and then of the octree
// stages' chunk jobs, of the conversion rank 0 runs with the same raw points, budget and options
// (convertSpilled with ConvertSource::ranks).
void prepareAsRank(const RawSpill& raw, SpillDirectory& directory, const OutOfCoreBudget& budget,
                   const BuildOptions& options, const Ranks& ranks, bool collectStrays);

// Throws UsageError naming the option (as on the command line) that is out of range.
void validateOptions(const BuildOptions& options);

// The options as JSON (the file's "parameters").
nlohmann::json optionsJson(const BuildOptions& options);

}  // namespace iso
