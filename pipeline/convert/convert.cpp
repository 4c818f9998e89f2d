// The conversion: the stages of points/, octree/ and output/ in order, timed, and the report.
#include "pipeline/convert/convert.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <glm/geometric.hpp>
#include <map>
#include <numeric>
#include <optional>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "iso/version.h"
#include "pipeline/analysis/measure.h"
#include "pipeline/analysis/visibility.h"
#include "pipeline/base/options.h"
#include "pipeline/base/process.h"
#include "pipeline/base/progress.h"
#include "pipeline/convert/checkpoints.h"
#include "pipeline/convert/corner_stages.h"
#include "base/image.h"
#include "pipeline/octree/field.h"
#include "pipeline/octree/octree.h"
#include "pipeline/outofcore/outofcore.h"
#include "pipeline/output/chunks.h"
#include "pipeline/output/keep_points.h"
#include "pipeline/output/lighting.h"
#include "pipeline/output/occlusion.h"
#include "pipeline/output/texture.h"
#include "pipeline/points/knn.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

using Clock = std::chrono::steady_clock;

// Times the stages one after the other and shows their progress.
class StageTimer {
 public:
  StageTimer(nlohmann::json& stages, const ConvertSource& source)
      : stages_(stages), source_(source) {}
  ~StageTimer() {
    if (source_.progress != nullptr) source_.progress->end();
  }
  // End the current stage (if any) and begin the next, of `total` units of work (0: unknown).
  void next(const std::string& name, uint64_t total = 0) {
    end();
    name_ = name;
    if (source_.progress != nullptr) source_.progress->begin(name, total);
  }
  void end() {
    const auto now = Clock::now();
    if (!name_.empty()) add(name_, std::chrono::duration<double>(now - start_).count());
    name_.clear();
    start_ = now;
  }
  // End the current stage without recording it (its parts are added instead).
  void discard() {
    name_.clear();
    end();
  }
  void add(const std::string& name, double seconds) {
    stages_.push_back({{"name", name}, {"seconds", seconds}});
    if (source_.onStage) source_.onStage(name, seconds);
  }

 private:
  nlohmann::json& stages_;
  const ConvertSource& source_;
  std::string name_;
  Clock::time_point start_ = Clock::now();
};

}  // namespace

void validateOptions(const BuildOptions& o) {
  const auto require = [](bool ok, const char* what) {
    if (!ok) throw UsageError(what);
  };
  require(o.neighbors >= 3 && o.neighbors <= 64, "--neighbors must be 3 to 64");
  require(std::isfinite(o.smoothing) && o.smoothing > 0.0, "--smoothing must be positive");
  require(o.leafPoints >= 1, "--leaf-points must be at least 1");
  require(o.maxDepth >= 1 && o.maxDepth <= 20, "--max-depth must be 1 to 20");
  require(std::isfinite(o.tolerance) && o.tolerance >= 0.0, "--tolerance must be 0 or more");
  require(o.cornerFit >= 0 && o.cornerFit <= 16, "--corner-fit must be 0 to 16 passes");
  require(o.normalBits == 8 || o.normalBits == 12, "--normal-bits must be 8 or 12");
  require(o.chunkNodes >= 64, "--chunk-nodes must be at least 64");
  require(o.zstdLevel >= 1 && o.zstdLevel <= 19, "--zstd-level must be 1 to 19");
  require(o.orientBlockPoints >= 16, "--orient-block-points must be at least 16");
  require(o.octreeChunkPoints >= 1024, "--octree-chunk-points must be at least 1024");
  const TextureOptions& t = o.texture;
  require(std::isfinite(t.scale) && t.scale >= 0.0, "--texture-scale must be positive");
  require(std::isfinite(t.sharpness) && t.sharpness >= 0.0 && t.sharpness <= 64.0,
          "--texture-sharpness must be 0 to 64");
  const OcclusionOptions& a = o.occlusion;
  require(a.rays >= 1 && a.rays <= 4096, "--ao-rays must be 1 to 4096");
  require(std::isfinite(a.radius) && a.radius >= 0.0, "--ao-radius must be positive");
  if (o.lighting.enabled) validateLightBake(o.lighting);
  require(o.pointBits >= 8 && o.pointBits <= 30, "--point-bits must be 8 to 30");
  require(o.keptPointsPerChunk >= 1 && o.keptPointsPerChunk <= kMaxPointsPerChunk,
          "kept points per chunk must be 1 to 2^20");
}

namespace {

// Whether all points lie on one line (then they define no surface).
bool isCollinear(const PointSet& points) {
  const auto farthestFrom = [&](const glm::vec3& from) {
    size_t best = 0;
    float bestD = -1.0f;
    for (size_t i = 0; i < points.size(); ++i) {
      const float d = glm::length(points.position[i] - from);
      if (d > bestD) {
        bestD = d;
        best = i;
      }
    }
    return best;
  };
  const glm::dvec3 a(points.position[farthestFrom(points.position[0])]);
  const glm::dvec3 b(points.position[farthestFrom(glm::vec3(a))]);
  const double length = glm::length(b - a);
  if (length == 0.0) return true;
  const glm::dvec3 d = (b - a) / length;
  for (const glm::vec3& p : points.position) {
    const glm::dvec3 v = glm::dvec3(p) - a;
    if (glm::length(v - glm::dot(v, d) * d) > 1e-6 * length) return false;
  }
  return true;
}

struct Prepared {
  Frame frame;
  PointSet points;
  size_t duplicates = 0;
};

// Throw ConvertError when the (merged) points define no surface.
void requireSurface(const PointSet& points) {
  if (points.size() < 3)
    throw ConvertError("a surface needs at least 3 distinct points; the input has " +
                       std::to_string(points.size()));
  if (isCollinear(points)) throw ConvertError("all points lie on one line: they define no surface");
}

Prepared prepare(const PointCloud& cloud) {
  Prepared p;
  p.frame = chooseFrame(cloud);
  p.points = makePointSet(cloud, p.frame);
  sortByKey(p.points);
  p.duplicates = mergeDuplicates(p.points);
  requireSurface(p.points);  // before the neighbour search, which needs a few points
  return p;
}

// The conversion report's visibility (pipeline/analysis/visibility.h): up to kVisibilityPoints of
// the accuracy sample, the 6 axis views and 2 random ones, pixels one spacing wide.
constexpr size_t kVisibilityPoints = 20000;

nlohmann::json visibilityReport(const Reader& written, std::span<const glm::dvec3> sample,
                                double spacing) {
  const size_t step =
      std::max<size_t>(1, (sample.size() + kVisibilityPoints - 1) / kVisibilityPoints);
  std::vector<glm::dvec3> points;
  for (size_t i = 0; i < sample.size(); i += step) points.push_back(sample[i]);
  VisibilityOptions options;
  options.randomViews = 2;
  nlohmann::json v = measureVisibility(written, points, spacing, options).json();
  v.erase("rays");
  return v;
}

nlohmann::json octreeJson(const Octree& tree, const OctreeStats& stats, size_t passive,
                          size_t splits) {
  std::map<int, uint64_t> leavesPerLevel, passivePerLevel;
  uint64_t internal = 0, leaves = 0, passiveLeaves = 0;
  int maxLevel = 0;
  for (const OctreeNode& n : tree.nodes) {
    if (n.kind == NodeKind::Internal) ++internal;
    if (!n.isFilled()) continue;
    ++leaves;
    ++leavesPerLevel[n.level];
    if (n.kind == NodeKind::Passive) {
      ++passiveLeaves;
      ++passivePerLevel[n.level];
    }
    maxLevel = std::max(maxLevel, int(n.level));
  }
  nlohmann::json perLevel = nlohmann::json::object();
  for (const auto& [level, count] : leavesPerLevel) perLevel[std::to_string(level)] = count;
  return {{"internal_nodes", internal},
          {"leaves", leaves},
          {"passive_leaves", passiveLeaves},
          {"leaves_per_level", perLevel},
          {"max_level", maxLevel},
          {"passive_marked", passive},
          {"balance_splits", splits},
          {"patch_splits", stats.testedPatches},
          {"patch_splits_too_far", stats.tooFar},
          {"patch_splits_uncovered", stats.uncovered},
          {"thin_splits", stats.thinSplits}};
}

}  // namespace

nlohmann::json optionsJson(const BuildOptions& o) {
  nlohmann::json out = {{"neighbors", o.neighbors},
                        {"smoothing", o.smoothing},
                        {"fit", nameOf(kFitNames, o.fit)},
                        {"orient", nameOf(kOrientNames, o.orient)},
                        {"leaf_points", o.leafPoints},
                        {"max_depth", o.maxDepth},
                        {"tolerance", o.tolerance},
                        {"corner_fit", o.cornerFit},
                        {"fill_holes", o.fillHoles},
                        {"trim_reach", o.trimReach},
                        {"normal_bits", o.normalBits},
                        {"chunk_nodes", o.chunkNodes},
                        {"zstd_level", o.zstdLevel},
                        {"remove_outliers", o.removeOutliers},
                        {"stray_group_points", o.strayGroupPoints},
                        {"orient_block_points", o.orientBlockPoints},
                        {"octree_chunk_points", o.octreeChunkPoints}};
  // Bakes are listed only when asked for, so files without them keep their bytes.
  if (o.texture.enabled())
    out["texture"] = {{"image", o.texture.image.filename().string()},
                      {"scale", o.texture.scale},
                      {"sharpness", o.texture.sharpness},
                      {"at", nameOf(kTextureAtNames, o.texture.at)}};
  if (o.occlusion.enabled)
    out["occlusion"] = {{"rays", o.occlusion.rays}, {"radius", o.occlusion.radius}};
  if (o.lighting.enabled) out["lighting"] = lightBakeJson(o.lighting);
  if (o.keepPoints) out["keep_points"] = {{"point_bits", o.pointBits}};
  if (!o.keepScalar.empty()) out["keep_scalar"] = o.keepScalar;
  return out;
}

namespace {

KeptValues keptValues(const BuildOptions& o) {
  return {.name = o.keepScalar, .density = o.keepScalar == "density", .neighbours = o.neighbors};
}

// Writes the input points into points chunks (`--keep-points`), in the final frame.
// `prepared`: the conversion's points, whose radii and normals the kept points take.
using KeepPoints =
    std::function<KeptPointsStats(Writer&, const FileHeader&, const PointSet& prepared)>;

nlohmann::json buildAndWrite(ReadyPoints& ready, uint64_t inputPoints,
                             const std::filesystem::path& output, const BuildOptions& options,
                             std::optional<LinearImage> textureImage, const KeepPoints& keep,
                             const ConvertSource& source, StageTimer& timer, nlohmann::json& report,
                             Clock::time_point started);

// The point stages in core, timed.
ReadyPoints prepareInCore(const PointCloud& input, const BuildOptions& options, StageTimer& timer,
                          bool collectStrays) {
  ReadyPoints ready;
  const PointCloud* cloud = &input;
  PointCloud filtered;
  timer.next("prepare", input.size());
  Prepared prepared = prepare(*cloud);
  timer.next("radii", input.size());
  auto tree = std::make_unique<PointIndex>(prepared.points.position);
  Neighbors neighbors = findNeighbors(prepared.points, *tree, options.neighbors);
  if (options.removeOutliers) {
    const Strays strays = findStrays(prepared.points.size(), neighbors, options.strayGroupPoints);
    if (strays.sparse + strays.grouped > 0) {  // choose the frame again without them
      filtered = withoutFlagged(*cloud, prepared.frame, prepared.points, strays.flagged,
                                collectStrays ? &ready.strays : nullptr);
      ready.outliers = {cloud->size() - filtered.size(), strays.sparse, strays.grouped};
      cloud = &filtered;
      timer.next("prepare", cloud->size());  // both stages again, as their own entries
      prepared = prepare(*cloud);
      timer.next("radii", cloud->size());
      tree = std::make_unique<PointIndex>(prepared.points.position);
      neighbors = findNeighbors(prepared.points, *tree, options.neighbors);
    }
  }
  PointSet& points = prepared.points;
  ready.radii = estimateRadii(points, neighbors);
  timer.next("normals", points.size());

  std::vector<uint8_t> wasEstimated(points.size(), 0);
  for (size_t i = 0; i < points.size(); ++i)
    wasEstimated[i] = points.normal.empty() || points.normal[i] == glm::vec3(0.0f);
  estimateNormals(points, neighbors);
  ready.normals =
      orientNormals(points, neighbors, options.orient, wasEstimated, options.orientBlockPoints);
  estimateRoughness(points, neighbors);
  ready.frame = prepared.frame;
  ready.duplicates = prepared.duplicates;
  ready.points = std::move(prepared.points);
  ready.index = std::move(tree);
  const size_t step = sampleStep(cloud->size(), kAccuracySamples);
  for (size_t i = 0; i < cloud->size(); i += step) ready.sample.push_back(cloud->positions[i]);
  return ready;
}

// The conversion around its point stages (`prepare`, in or out of core): options checked, stages
// timed, then the octree stages and the file.
nlohmann::json convertWith(uint64_t inputPoints, const std::filesystem::path& output,
                           const BuildOptions& options, const ConvertSource& source,
                           const std::function<ReadyPoints(StageTimer&)>& prepare,
                           const KeepPoints& keep) {
  validateOptions(options);
  if (inputPoints == 0) throw ConvertError("no points to convert");
  const auto started = Clock::now();
  // Read first: a bad image fails before any work. Wider than 8192 texels it is box-filtered
  // down (12 bytes a texel in memory; leaves hold far less detail than that).
  std::optional<LinearImage> textureImage;
  if (options.texture.enabled()) textureImage = readLinearImage(options.texture.image, 8192);
  nlohmann::json report;
  report["stages"] = nlohmann::json::array();
  StageTimer timer(report["stages"], source);
  if (source.readSeconds > 0.0) timer.add("read", source.readSeconds);
  std::optional<ReadyPoints> resumed;
  if (source.resume != nullptr && source.resume->has(kPointsCheckpoint)) {
    timer.next("resume points", inputPoints);
    resumed = loadPoints(*source.resume);
    if (resumed) report["resumed"] = {{"from", "points"}, {"state", source.resume->directory()}};
  }
  ReadyPoints ready = resumed ? std::move(*resumed) : prepare(timer);
  // A chunked run's jobs are its checkpoints: a run killed after them redoes only the merge, which
  // costs about three of the corners' checkpoint (specs/pipeline.md §15, "Resume").
  if (source.resume != nullptr && !resumed && !report.contains("octree_chunks")) {
    timer.next("checkpoint");
    savePoints(*source.resume, ready);
    source.resume->removeStartingWith("chunk-");  // the points' checkpoint holds them all
  }
  if (source.onStrays) source.onStrays(std::move(ready.strays));
  return buildAndWrite(ready, inputPoints, output, options, std::move(textureImage), keep, source,
                       timer, report, started);
}

// ---- the measures of a distributed run: rank 1 measures what a viewer shows while rank 0
// measures the distances (the same code on the same file: the same numbers, the same bytes). They
// pass the request and the answer as checkpoints in the shared directory.

constexpr const char* kMeasuresFingerprint = "the measures of one run";
constexpr const char* kMeasureRequest = "request";
constexpr const char* kSharedVisibility = "visibility";

ResumeState sharedMeasures(const Ranks& ranks) {
  return ResumeState(ranks.shared / "measures", kMeasuresFingerprint);
}

// Rank 0, once the file is written: asks rank 1 to measure its visibility.
void askForVisibility(const Ranks& ranks, const ResumeState& share,
                      const std::filesystem::path& written, double spacing,
                      const std::vector<glm::dvec3>& sample) {
  const std::unique_ptr<CheckpointWriter> out = share.create(kMeasureRequest);
  // Absolute: the ranks may have started in other folders.
  out->json(kMeasureRequest, {{"file", std::filesystem::absolute(written).string()},
                              {"spacing", spacing}});
  out->array("sample", sample);
  out->commit();
  std::vector<std::byte> word{std::byte{1}};
  ranks.broadcast(word);
}

// Rank 0, once its own measure is done: rank 1's visibility, or "unseen" when rank 1 could not
// see the file (rank 0 measures it then).
nlohmann::json visibilityOfRank1(const Ranks& ranks, ResumeState& share) {
  ranks.barrier();
  const std::unique_ptr<CheckpointReader> in = share.open(kSharedVisibility);
  if (!in)
    throw std::runtime_error("rank 1's visibility measure cannot be read from " +
                             share.path(kSharedVisibility).string());
  nlohmann::json visibility = in->json(kSharedVisibility);
  in->finish();
  share.finish();
  return visibility;
}

// A rank other than 0, once its part of the octree stages is done: rank 1 measures the written
// file's visibility and keeps it in the shared directory for rank 0 ("unseen" when the file is
// not on a file system it sees).
void measureAsRank(const Ranks& ranks) {
  std::vector<std::byte> word;
  ranks.broadcast(word);
  if (ranks.rank == 1 && !word.empty()) {
    ResumeState share = sharedMeasures(ranks);
    const std::unique_ptr<CheckpointReader> in = share.open(kMeasureRequest);
    if (!in)
      throw std::runtime_error("rank 0's measure request cannot be read from " +
                               share.path(kMeasureRequest).string());
    const nlohmann::json request = in->json(kMeasureRequest);
    std::vector<glm::dvec3> sample;
    in->array("sample", sample);
    in->finish();
    const std::string file = request["file"];
    std::error_code error;
    nlohmann::json visibility = "unseen";
    if (std::filesystem::is_regular_file(file, error))
      visibility = visibilityReport(Reader::open(file), sample, request["spacing"].get<double>());
    const std::unique_ptr<CheckpointWriter> out = share.create(kSharedVisibility);
    out->json(kSharedVisibility, visibility);
    out->commit();
  }
  ranks.barrier();  // rank 0 reads it after this
}

}  // namespace

nlohmann::json coordinateSystemOf(const nlohmann::json& inputs) {
  // Two inputs declare the same system when these agree (a name or the records it came from may
  // differ).
  const auto identity = [](const nlohmann::json& crs) {
    nlohmann::json id;
    for (const char* key : {"wkt", "epsg", "vertical_epsg"})
      id[key] = crs.value(key, nlohmann::json());
    return id;
  };
  nlohmann::json crs;
  for (const nlohmann::json& input : inputs) {
    if (!input.contains("crs")) continue;
    if (crs.is_null()) {
      crs = input["crs"];
      crs["input"] = input.value("file", "");
    } else if (identity(input["crs"]) != identity(crs)) {
      crs["differing_inputs"].push_back(input.value("file", ""));
    }
  }
  return crs;
}

nlohmann::json convertToIso(const PointCloud& input, const std::filesystem::path& output,
                            const BuildOptions& options, const ConvertSource& source) {
  return convertWith(
      input.size(), output, options, source,
      [&](StageTimer& timer) {
        return prepareInCore(input, options, timer, bool(source.onStrays));
      },
      [&](Writer& writer, const FileHeader& header, const PointSet& prepared) {
        return keepPoints(writer, input, header, options.pointBits, options.keptPointsPerChunk,
                          &prepared, keptValues(options));
      });
}

OutOfCoreBudget OutOfCoreBudget::forMemory(uint64_t memory) {
  return {std::max<uint64_t>(memory / 600, 1), memory, std::max<uint64_t>(memory / 32, 4096)};
}

nlohmann::json convertSpilled(const RawSpill& raw, SpillDirectory& directory,
                              const OutOfCoreBudget& budget, const std::filesystem::path& output,
                              const BuildOptions& options, const ConvertSource& source) {
  std::optional<SpillArea> area;
  if (budget.memory > 0) area.emplace(directory.path(), budget.memory, budget.minSpilledBytes);
  return convertWith(
      raw.size(), output, options, source,
      [&](StageTimer& timer) {
        const auto stage = [&](const std::string& name, uint64_t total) {
          timer.next(name, total);
        };
        ReadyPoints ready = prepareOutOfCore(raw, directory, options, budget.maxChunkPoints, stage,
                                             bool(source.onStrays), source.ranks, source.resume);
        requireSurface(ready.points);  // known once every chunk's duplicates are merged
        return ready;
      },
      [&](Writer& writer, const FileHeader& header, const PointSet& prepared) {
        return keepPoints(writer, raw, directory, header, options.pointBits, budget.maxChunkPoints,
                          options.keptPointsPerChunk, &prepared, keptValues(options));
      });
}

void prepareAsRank(const RawSpill& raw, SpillDirectory& directory, const OutOfCoreBudget& budget,
                   const BuildOptions& options, const Ranks& ranks, bool collectStrays) {
  std::optional<SpillArea> area;
  if (budget.memory > 0) area.emplace(directory.path(), budget.memory, budget.minSpilledBytes);
  prepareOutOfCore(
      raw, directory, options, budget.maxChunkPoints, [](const std::string&, uint64_t) {},
      collectStrays, &ranks);
  runCornerStagesAsRank(options, ranks);
  measureAsRank(ranks);
}

namespace {

// The texture (`--texture`), read before any work. Sampled at the points, it becomes their
// colors here, in or out of core alike.
std::optional<TriplanarTexture> textureOf(std::optional<LinearImage> image, const TextureOptions& t,
                                          PointSet& points, const Frame& frame, StageTimer& timer,
                                          nlohmann::json& report) {
  if (!image) return std::nullopt;
  const double scale = t.scale > 0.0 ? t.scale : frame.size;
  report["texture"] = {{"image", t.image.filename().string()},
                       {"width", image->width},
                       {"height", image->height},
                       {"scale", scale},
                       {"sharpness", t.sharpness},
                       {"at", nameOf(kTextureAtNames, t.at)},
                       {"modulates_point_colors", points.hasColors()}};
  std::optional<TriplanarTexture> texture(std::in_place, std::move(*image), scale, t.sharpness);
  if (t.at == TextureAt::Points) {
    timer.next("texture", points.size());
    texturePoints(points, frame, *texture);
  }
  return texture;
}

// What the point stages did, in the report.
void reportPoints(const ReadyPoints& ready, uint64_t input, uint64_t nonFinite,
                  nlohmann::json& report) {
  const PointSet& points = ready.points;
  report["points"] = {{"input", input},
                      {"non_finite_dropped", nonFinite},
                      {"duplicates_merged", ready.duplicates},
                      {"outliers_removed", ready.outliers.removed},
                      {"used", points.size()}};
  report["normals"] = {{"estimated", ready.normals.estimated},
                       {"from_input", points.size() - ready.normals.estimated},
                       {"flipped_to_agree", ready.normals.flipped}};
  if (!ready.outOfCore.is_null()) report["out_of_core"] = ready.outOfCore;
  report["points"]["outliers"] = {{"sparse", ready.outliers.sparse},
                                  {"in_small_groups", ready.outliers.grouped}};
  report["spacing"] = ready.radii.spacing * ready.frame.size;
  report["median_radius"] = ready.radii.medianRadius * ready.frame.size;
}

// The written file in the report: its size, and what it makes of the sampled input points (the
// distance to its zero set, what the viewer shows of them). With ranks (rank 0 of several), rank
// 1 measures the visibility meanwhile (measureAsRank).
void reportWritten(const std::filesystem::path& written, const WriteStats& stats,
                   const std::vector<glm::dvec3>& sample, uint64_t inputPoints, double spacing,
                   const Frame& frame, const Ranks* ranks, StageTimer& timer,
                   nlohmann::json& report) {
  std::optional<ResumeState> share;
  if (ranks != nullptr) {
    share.emplace(sharedMeasures(*ranks));
    askForVisibility(*ranks, *share, written, spacing, sample);
  }
  timer.next("accuracy");
  const uint64_t leaves = report["octree"]["leaves"].get<uint64_t>();
  report["file"] = {
      {"chunks", stats.chunks},
      {"bytes_without_metadata", stats.fileBytesWithoutMetadata},
      {"bytes_per_leaf",
       double(stats.fileBytesWithoutMetadata) / double(std::max<uint64_t>(leaves, 1))},
      {"bytes_per_point", double(stats.fileBytesWithoutMetadata) / double(inputPoints)}};
  const Reader writtenReader = Reader::open(written);
  // Regions of about a quarter of the memory a conversion is held to (--memory), at the measure's
  // kDecodedLeafBytes a leaf; the distances do not depend on it.
  const uint64_t limit = SpillArea::residentLimit();
  const uint64_t regionLeaves =
      limit > 0 ? std::clamp<uint64_t>(limit / 4 / kDecodedLeafBytes, 50000, kRegionLeaves)
                : kRegionLeaves;
  const DistanceStats d = pointsToZeroSet(writtenReader, frame, sample, false, regionLeaves);
  report["accuracy"] = {{"samples", d.samples},
                        {"unprojected", d.unprojected},
                        {"rms", d.rms},
                        {"max", d.max},
                        {"mean", d.mean},
                        {"rms_over_spacing", d.rms / spacing},
                        {"max_over_spacing", d.max / spacing}};
  timer.next("visibility");
  nlohmann::json visibility = share ? visibilityOfRank1(*ranks, *share) : "unseen";
  if (share) report["out_of_core"]["visibility_rank"] = visibility.is_string() ? 0 : 1;
  if (visibility.is_string()) visibility = visibilityReport(writtenReader, sample, spacing);
  report["visibility"] = std::move(visibility);
  timer.end();
}

// Time, speed, memory and temporary disk of the whole conversion, in the report.
void reportRun(double seconds, double pointsPerSecond, nlohmann::json& report) {
  report["seconds"] = seconds;
  report["points_per_second"] = pointsPerSecond;
  report["peak_rss_bytes"] = peakRssBytes();
  if (report["out_of_core"].is_null()) return;
  const SpillArea::Stats spilled = SpillArea::stats();
  report["out_of_core"]["spilled_bytes_peak"] = spilled.peakBytes;
  report["out_of_core"]["spilled_arrays"] = spilled.arrays;
  report["out_of_core"]["page_releases"] = spilled.releases;
  // All temporary files at once: the points' record files and the spilled arrays.
  const TemporaryDiskStats disk = temporaryDiskStats();
  report["out_of_core"]["temporary_disk_peak"] = disk.peakBytes;
  if (disk.limit > 0) report["out_of_core"]["temporary_disk_limit"] = disk.limit;
}

// Throw ConvertError when the points' cube is one an .iso file cannot hold (FrameProblem: points
// more than 2^64 units apart or from the origin).
void requireFrame(const Frame& frame) {
  const std::optional<FrameProblem> problem = frameProblem(frame);
  if (!problem) return;
  char cube[160];
  std::snprintf(cube, sizeof cube, "origin (%.9g, %.9g, %.9g), size %.9g", frame.origin[0],
                frame.origin[1], frame.origin[2], frame.size);
  throw ConvertError("the points' cube (" + std::string(cube) +
                     ") is beyond what an .iso file holds: " + std::string(problem->reason));
}

// The run's ranks when there are several (a distributed run's rank 0), else null.
const Ranks* ranksOf(const ConvertSource& source) {
  return source.ranks != nullptr && source.ranks->count > 1 ? source.ranks : nullptr;
}

// The octree stages before the level of detail (pipeline/convert/corner_stages.h): in one run, or
// as chunk jobs when the points are many, with their counts and times in the report.
CornerStageResults buildCornerStages(PointSet& points, const SdfEvaluator& sdf,
                                     const BuildOptions& options, const RadiusStats& radii,
                                     const OctreeChunkPlan& plan, StageTimer& timer,
                                     nlohmann::json& report, const ConvertSource& source) {
  const Ranks* ranks = ranksOf(source);
  if (plan.chunks() == 1) {
    CornerStageResults r = runCornerStages(points, sdf, options, radii, 0,
                                           [&](const char* stage) { timer.next(stage); });
    points.roughness = {};  // only the octree's tolerance reads it
    return r;
  }
  timer.next("octree chunks", points.size());
  CornerStageSeconds seconds;
  ChunkRunStats stats;
  CornerStageResults r = runCornerStagesByChunk(
      points, plan, sdf, options, radii, seconds, stats, [](uint64_t done) { progressAdvance(done); },
      source.resume, ranks);
  if (stats.resumed > 0) report["resumed"]["octree_chunks"] = stats.resumed;
  points.roughness = {};
  timer.discard();  // recorded by part below
  timer.add("chunk points", seconds.load);
  timer.add("octree", seconds.octree);
  timer.add("passive+balance", seconds.passiveBalance);
  timer.add("corners", seconds.corners);
  timer.add("chunk lod", seconds.lod);
  if (ranks != nullptr) timer.add("ranks", seconds.ranks);
  timer.add("chunk merge", seconds.merge);
  report["octree_chunks"] = {{"chunks", plan.chunks()},
                             {"cell_level", plan.cellLevel},
                             {"halo_level", plan.haloLevel},
                             {"halo_points", stats.haloPoints},
                             {"seam_splits", stats.seamSplits},
                             {"seam_fills", stats.seamFills},
                             {"lod_samples", r.lod.size()}};
  return r;
}

nlohmann::json buildAndWrite(ReadyPoints& ready, uint64_t inputPoints,
                             const std::filesystem::path& output, const BuildOptions& options,
                             std::optional<LinearImage> textureImage, const KeepPoints& keep,
                             const ConvertSource& source, StageTimer& timer, nlohmann::json& report,
                             Clock::time_point started) {
  requireFrame(ready.frame);
  PointSet& points = ready.points;
  const Frame& frame = ready.frame;
  const RadiusStats& radii = ready.radii;
  points.source = {};  // the octree stages do not need it: 4 bytes a point

  const bool inputColors = points.hasColors();
  std::optional<TriplanarTexture> texture =
      textureOf(std::move(textureImage), options.texture, points, frame, timer, report);

  // The chunk jobs' partition: the corner stages' and the level of detail's.
  const OctreeChunkPlan plan = planOctreeChunks(points, radii, options);
  std::optional<CornerStageResults> resumed;
  if (source.resume != nullptr && report.contains("resumed") &&
      source.resume->has(kCornersCheckpoint)) {
    timer.next("resume corners");
    resumed = loadCornerStage(*source.resume);
    if (resumed) report["resumed"]["from"] = "corners";
  }
  // The other ranks start on their chunk jobs (or are told that rank 0 runs them alone) before
  // rank 0 builds the point index, which only its own stages read.
  if (const Ranks* ranks = ranksOf(source); ranks != nullptr && !resumed) {
    timer.next("ranks");
    tellRanks(*ranks, plan.chunks() > 1 ? &points : nullptr, radii);
  }
  if (!ready.index) {
    timer.next("index", points.size());
    ready.index = std::make_unique<PointIndex>(points.position);
  }
  // The signed distance and its point index are needed until the level-of-detail corners.
  auto sdf = std::make_unique<SdfEvaluator>(points, *ready.index, options.smoothing, options.fit);
  CornerStageResults built =
      resumed ? std::move(*resumed)
              : buildCornerStages(points, *sdf, options, radii, plan, timer, report, source);
  // A chunked run's jobs are its checkpoints: a run killed after them redoes only the merge, which
  // costs about three of the corners' checkpoint (specs/pipeline.md §15, "Resume").
  if (source.resume != nullptr && !resumed && plan.chunks() == 1) {
    timer.next("checkpoint");
    saveCornerStage(*source.resume, built);
    source.resume->removeStartingWith(kOctreeChunkPrefix);  // the corners' checkpoint holds them
  }
  points.roughness = {};  // a resumed run's points have it still
  Octree& octree = built.octree;
  Closure& closure = built.closure;
  const CornerField& corners = closure.corners;
  const HangingCorners& hanging = closure.hanging;
  timer.next("lod");
  // The points' signed distance and index go once the levels that read them are done: the writer
  // reads points, not neighbours.
  // A chunk run's corners by chunk (cell_index.h), in the order its tree's nodes come.
  LodField lod = sampleLodCorners(
      octree, points, *sdf, options,
      [&] {
        sdf.reset();
        ready.index.reset();
      },
      plan.chunks() > 1 ? plan.cut() : CellCut{}, &built.lod,
      plan.chunks() > 1 ? &plan.lodProxyLevels : nullptr);
  built.lod = {};
  if (texture && options.texture.at == TextureAt::Corners) {
    timer.next("texture", corners.size() + lod.value.size());
    textureCorners(closure.corners, lod, frame, *texture, inputColors);
  }
  timer.next("write");

  const double spacing = radii.spacing * frame.size;
  reportPoints(ready, inputPoints + source.nonFiniteDropped, source.nonFiniteDropped, report);
  report["octree"] = octreeJson(octree, built.stats, built.passive, built.splits);
  report["octree"]["closure_filled"] = closure.filled;
  report["octree"]["closure_refilled"] = closure.refilled;
  report["octree"]["trimmed"] = built.trimmed;
  report["corners"] = {
      {"leaf", closure.cornersInUse}, {"hanging", hanging.size()}, {"lod", lod.value.size()}};
  if (plan.chunks() > 1) report["corners"]["lod_from_jobs"] = lod.fromSamples;

  WriteInput write{.tree = &octree,
                   .points = &points,
                   .corners = &corners,
                   .hanging = &hanging,
                   .lod = &lod,
                   .frame = frame,
                   .metadata = "{}",
                   .colors = points.hasColors() || texture.has_value(),
                   .options = options};
  if (options.occlusion.enabled)
    write.passes.push_back({withOcclusion, [&](const Reader& written, Writer& out) {
                              timer.next("occlusion");
                              const double radius = options.occlusion.radius > 0.0
                                                        ? options.occlusion.radius
                                                        : 0.1 * frame.size;
                              const OcclusionStats s = bakeOcclusion(
                                  written, out, options.occlusion.rays, radius / frame.size);
                              report["occlusion"] = {{"rays_per_corner", options.occlusion.rays},
                                                     {"radius", radius},
                                                     {"corners", s.corners},
                                                     {"unprojected", s.unprojected},
                                                     {"mean", s.mean}};
                            }});
  if (options.lighting.enabled)
    write.passes.push_back({withLighting, [&](const Reader& written, Writer& out) {
                              timer.next("light bake");
                              report["lighting"] =
                                  bakeLighting(written, out, options.lighting).json();
                            }});
  if (options.keepPoints || source.volumePoints != nullptr)
    write.moreChunks = [&](Writer& out, const FileHeader& header) {
      if (options.keepPoints) {
        timer.next("keep points", inputPoints);
        const KeptPointsStats kept = keep(out, header, points);
        report["kept_points"] = kept.json();
        report["kept_points"]["max_error_over_spacing"] = kept.maxError / spacing;
      }
      points = PointSet{};
      if (source.volumePoints != nullptr) {
        const PointCloud& volume = *source.volumePoints;
        timer.next("volume points", volume.size());
        const KeptPointsStats kept =
            keepPoints(out, volume, header, options.pointBits, options.keptPointsPerChunk, nullptr,
                       {.name = volume.extraNames.empty() ? "" : volume.extraNames[0],
                        .density = false,
                        .neighbours = options.neighbors},
                       true);
        report["volume_points"] = kept.json();
      }
    };
  // The file keeps what the data and options determine, not timings or memory, so that the same
  // input gives the same bytes on any machine and any number of threads.
  const auto metadata = [&](nlohmann::json r) {
    for (const char* key :
         {"stages", "seconds", "points_per_second", "peak_rss_bytes", "out_of_core", "resumed"})
      r.erase(key);
    if (r.contains("lighting")) r["lighting"].erase("timing");
    nlohmann::json m{{"generator", std::string("iso ") + ISO_VERSION},
                     {"inputs", source.inputs},
                     {"parameters", optionsJson(options)},
                     {"report", r}};
    if (nlohmann::json crs = coordinateSystemOf(source.inputs); !crs.is_null())
      m["crs"] = std::move(crs);
    if (options.lighting.enabled) {  // as iso bake writes it
      m["lighting"] = lightBakeJson(options.lighting);
      if (r.contains("lighting")) m["lighting"]["report"] = r["lighting"];
    }
    return m;
  };
  write.metadata = metadata(report).dump();
  write.release = [&] {
    octree = Octree{};
    closure = Closure{};
    lod = LodField{};
    if (!options.keepPoints) {
      points = PointSet{};
      return;
    }
    // The kept points take the radii and normals of these: keep only what they read.
    points.color = {};
    points.weight = {};
    points.roughness = {};
  };
  writeSurfaceFile(
      output, write, [&](const std::filesystem::path& written, const WriteStats& stats) {
        reportWritten(written, stats, ready.sample, inputPoints, spacing, frame,
                      source.ranks != nullptr && source.ranks->count > 1 ? source.ranks : nullptr,
                      timer, report);
        const double seconds =
            std::chrono::duration<double>(Clock::now() - started).count() + source.readSeconds;
        reportRun(seconds, double(inputPoints + source.nonFiniteDropped) / seconds, report);
        return metadata(report).dump();
      });
  return report;
}

}  // namespace

}  // namespace iso
