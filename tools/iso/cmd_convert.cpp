// `iso convert IN... -o OUT.iso`: points to an Implicit Surface Octree, with the conversion report.
#include <fmt/core.h>

#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <optional>

#include "iso/error.h"
#include "iso/points.h"
#include "iso/temporary_files.h"
#include "iso/version.h"
#include "pipeline/base/buffers.h"
#include "pipeline/base/checkpoint.h"
#include "pipeline/base/files.h"
#include "pipeline/base/options.h"
#include "pipeline/convert/convert.h"
#include "base/image.h"
#include "pipeline/io/ply.h"
#include "pipeline/octree/octree.h"
#include "pipeline/outofcore/spill.h"
#include "tools/iso/commands.h"
#include "tools/iso/inputs.h"
#include "tools/iso/interrupt.h"
#include "tools/iso/light_bake.h"
#include "tools/iso/ranks.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

struct Options {
  std::vector<std::string> inputs;
  std::string output;
  std::string columns;
  std::string fit = "sphere";
  std::string orient = "auto";
  std::string memory = "auto";                 // --memory
  std::optional<uint64_t> chunkPoints;         // --chunk-points; default: from --memory
  std::string tmp;                             // --tmp; default: the output's directory
  std::string maxTemp = "auto";                // --max-temp
  std::string report;                          // --report FILE
  std::string writeStrays;                     // --write-strays FILE.ply
  std::string progress = "auto";               // auto, line, json, none
  std::string texture, textureAt = "corners";  // --texture, --texture-at
  std::string volumePoints, volumeColumns;       // --volume-points, --volume-columns
  std::string bakeLight;                         // --bake-light SCENE
  int bounces = LightBakeOptions{}.bounces, bakeRays = LightBakeOptions{}.rays;
  int threads = 0;                             // 0: all cores
  bool force = false, json = false, quiet = false, keepOutliers = false;
  bool resume = false;  // --resume
  BuildOptions build;
};

void printReport(const nlohmann::json& r, const Options& o) {
  const uint64_t input = r["points"]["input"].get<uint64_t>();
  fmt::print("{}: {} points → {} leaves in {:.2f} s ({} points/s), peak memory {}\n", o.output,
             withSeparators(input), withSeparators(r["octree"]["leaves"].get<uint64_t>()),
             r["seconds"].get<double>(),
             withSeparators(uint64_t(r["points_per_second"].get<double>())),
             byteSize(r["peak_rss_bytes"].get<uint64_t>()));
  fmt::print("  {:<16} {:>8} {:>14}\n", "stage", "seconds", "points/s");
  for (const auto& s : r["stages"]) {
    const double seconds = s["seconds"].get<double>();
    fmt::print("  {:<16} {:>8.3f} {:>14}\n", s["name"].get<std::string>(), seconds,
               seconds > 0 ? withSeparators(uint64_t(double(input) / seconds)) : "-");
  }
  if (r.contains("resumed"))
    fmt::print("  resumed: from the end of the {} stages, kept in {}\n",
               r["resumed"]["from"] == "points" ? "point" : "corner",
               r["resumed"]["state"].get<std::string>());
  const auto& p = r["points"];
  fmt::print("  points: {} used ({} duplicates merged, {} strays removed, {} non-finite dropped)\n",
             withSeparators(p["used"].get<uint64_t>()),
             withSeparators(p["duplicates_merged"].get<uint64_t>()),
             withSeparators(p["outliers_removed"].get<uint64_t>()),
             withSeparators(p["non_finite_dropped"].get<uint64_t>()));
  if (p["outliers_removed"].get<uint64_t>() > 0)
    fmt::print(
        "  strays: {} in groups of fewer than {} points, {} in groups far sparser than the scan\n",
        withSeparators(p["outliers"]["in_small_groups"].get<uint64_t>()), o.build.strayGroupPoints,
        withSeparators(p["outliers"]["sparse"].get<uint64_t>()));
  fmt::print(
      "  normals: {} from the input, {} estimated, {} flipped to agree with their neighbours\n",
      withSeparators(r["normals"]["from_input"].get<uint64_t>()),
      withSeparators(r["normals"]["estimated"].get<uint64_t>()),
      withSeparators(r["normals"]["flipped_to_agree"].get<uint64_t>()));
  std::string perLevel;
  for (const auto& [level, count] : r["octree"]["leaves_per_level"].items())
    perLevel += fmt::format(" L{}:{}", level, withSeparators(count.get<uint64_t>()));
  fmt::print("  leaves per level:{} ({} passive)\n", perLevel,
             withSeparators(r["octree"]["passive_leaves"].get<uint64_t>()));
  const auto& f = r["file"];
  const uint64_t fileChunks = f["chunks"].get<uint64_t>();
  fmt::print("  size: {} in {} chunk{}: {:.2f} bytes/leaf, {:.3f} bytes/point\n",
             byteSize(f["bytes_without_metadata"].get<uint64_t>()), fileChunks,
             fileChunks == 1 ? "" : "s", f["bytes_per_leaf"].get<double>(),
             f["bytes_per_point"].get<double>());
  if (r.contains("out_of_core")) {
    const auto& c = r["out_of_core"];
    const uint64_t chunks = c["chunks"].get<uint64_t>();
    fmt::print("  streamed: {} chunk{} of at most {} points, halos {} points\n",
               withSeparators(chunks), chunks == 1 ? "" : "s",
               withSeparators(c["max_chunk_points"].get<uint64_t>()),
               withSeparators(c["halo_points"].get<uint64_t>()));
    std::string disk =
        "  temporary disk: " + byteSize(c.value("temporary_disk_peak", uint64_t{0})) + " at most";
    if (c.contains("temporary_disk_limit"))
      disk += " (--max-temp " + byteSize(c["temporary_disk_limit"].get<uint64_t>()) + ")";
    disk += ": the points' files " + byteSize(c["temporary_bytes_peak"].get<uint64_t>());
    if (c.value("spilled_arrays", uint64_t{0}) > 0)
      disk += fmt::format(", {} spilled arrays {} (pages dropped {} times)",
                          withSeparators(c["spilled_arrays"].get<uint64_t>()),
                          byteSize(c["spilled_bytes_peak"].get<uint64_t>()),
                          withSeparators(c["page_releases"].get<uint64_t>()));
    fmt::print("{}\n", disk);
  }
  if (r.contains("texture")) {
    const auto& t = r["texture"];
    fmt::print(
        "  texture: {} ({}×{}) sampled at the {}, one repeat per {:.6g}, sharpness {:.3g}{}\n",
        t["image"].get<std::string>(), t["width"].get<uint32_t>(), t["height"].get<uint32_t>(),
        t["at"].get<std::string>(), t["scale"].get<double>(), t["sharpness"].get<double>(),
        t["modulates_point_colors"].get<bool>() ? ", times the points' colors" : "");
  }
  if (r.contains("occlusion")) {
    const auto& c = r["occlusion"];
    fmt::print(
        "  ambient occlusion: {} corners, {} rays each within {:.6g}: mean {:.3f}{}\n",
        withSeparators(c["corners"].get<uint64_t>()), c["rays_per_corner"].get<int>(),
        c["radius"].get<double>(), c["mean"].get<double>(),
        c["unprojected"].get<uint64_t>() > 0
            ? fmt::format(" ({} not projected)", withSeparators(c["unprojected"].get<uint64_t>()))
            : "");
  }
  if (r.contains("lighting")) printLightBake(r["lighting"]);
  if (r.contains("kept_points")) {
    const auto& k = r["kept_points"];
    fmt::print(
        "  kept points: {} in {} chunk{}{}, {} ({:.2f} bytes/point), positions within {:.3g} "
        "({:.3g} spacings){}\n",
        withSeparators(k["points"].get<uint64_t>()), withSeparators(k["chunks"].get<uint64_t>()),
        k["chunks"].get<uint64_t>() == 1 ? "" : "s",
        k.value("subsample_chunks", uint64_t{0}) > 0
            ? fmt::format(" and {} subsample chunks of {} points",
                          withSeparators(k["subsample_chunks"].get<uint64_t>()),
                          withSeparators(k["subsample_points"].get<uint64_t>()))
            : "",
        byteSize(k["bytes"].get<uint64_t>()),
        k["bytes_per_point"].get<double>(), k["max_error"].get<double>(),
        k["max_error_over_spacing"].get<double>(),
        k["coarser_chunks"].get<uint64_t>() > 0
            ? fmt::format(" ({} chunks of far outliers at a coarser step)",
                          withSeparators(k["coarser_chunks"].get<uint64_t>()))
            : "");
  }
  // The values kept with the points (--keep-scalar) and the volume points (--volume-points).
  const auto values = [](const nlohmann::json& k) {
    if (!k.contains("values") || k["values"].is_null()) return std::string();
    const auto& v = k["values"];
    return fmt::format(", with their {} ({})", v["name"].get<std::string>(),
                       byteSize(v["bytes"].get<uint64_t>()));
  };
  if (r.contains("kept_points") && !values(r["kept_points"]).empty())
    fmt::print("  kept points{}\n", values(r["kept_points"]));
  if (r.contains("volume_points")) {
    const auto& v = r["volume_points"];
    fmt::print("  volume points: {} in {} chunk{}, {}{}\n",
               withSeparators(v["points"].get<uint64_t>()),
               withSeparators(v["chunks"].get<uint64_t>()),
               v["chunks"].get<uint64_t>() == 1 ? "" : "s", byteSize(v["bytes"].get<uint64_t>()),
               values(v));
  }
  const auto& a = r["accuracy"];
  fmt::print(
      "  accuracy: {} input points to the zero set: RMS {:.3f}, max {:.3f} spacings "
      "(spacing {:.6g}; {} not projected)\n",
      withSeparators(a["samples"].get<uint64_t>()), a["rms_over_spacing"].get<double>(),
      a["max_over_spacing"].get<double>(), r["spacing"].get<double>(),
      withSeparators(a["unprojected"].get<uint64_t>()));
  const auto& v = r["visibility"];
  fmt::print(
      "  visibility: {:.3f} % of {} points seen through in {} views (worst view {:.3f} %, {} "
      "inside the points' outline), depth error median {:.3f} spacings\n",
      100.0 * v["seen_through_fraction"].get<double>(), withSeparators(v["points"].get<uint64_t>()),
      v["views"].get<uint64_t>(), 100.0 * v["worst_view_fraction"].get<double>(),
      withSeparators(v["seen_through_inside"].get<uint64_t>()),
      v["depth_error_median"].get<double>());
}

// The inputs' coordinate system, kept in the file's metadata: said unless quiet; inputs that
// declare another one are warned about even then.
void reportCoordinateSystem(const nlohmann::json& crs, bool quiet) {
  if (crs.is_null()) return;
  if (!quiet)
    fmt::print(stderr, "coordinate system: {} (kept in the file's metadata)\n",
               describeCoordinateSystem(crs));
  for (const auto& other : crs.value("differing_inputs", nlohmann::json::array()))
    fmt::print(stderr,
               "warning: {} declares another coordinate system than {}: the file's \"crs\" is "
               "the first one's (each input's is in its \"inputs\" entry)\n",
               other.get<std::string>(), crs["input"].get<std::string>());
}

// Bytes from a size (parseSize); "auto": half the physical memory.
uint64_t parseBytes(const std::string& text, const char* option) {
  if (text == "auto")
    return uint64_t(sysconf(_SC_PHYS_PAGES)) * uint64_t(sysconf(_SC_PAGE_SIZE)) / 2;
  return parseSize(text, option);
}

// --memory: a size no smaller than the smallest budget a conversion keeps to; auto: half the
// physical memory, at least that.
uint64_t memoryBudget(const std::string& text) {
  constexpr uint64_t smallest = OutOfCoreBudget::kSmallestMemory;
  const uint64_t memory = parseBytes(text, "--memory");
  if (text == "auto") return std::max(memory, smallest);
  if (memory < smallest)
    throw UsageError(fmt::format(
        "--memory {}: below the smallest budget a conversion keeps to, {}M", text, smallest >> 20));
  return memory;
}

// The budget of an out-of-core conversion: --memory's, with --chunk-points when given.
OutOfCoreBudget outOfCoreBudget(const Options& o, uint64_t memory) {
  OutOfCoreBudget budget = OutOfCoreBudget::forMemory(memory);
  if (o.chunkPoints) budget.maxChunkPoints = *o.chunkPoints;
  return budget;
}

// --max-temp: a size, or auto: 90 % of the space free on the file system of the temporary files.
uint64_t temporaryDiskLimit(const std::string& text, const std::filesystem::path& tmp) {
  if (text != "auto") return parseBytes(text, "--max-temp");
  std::error_code error;
  const std::filesystem::space_info space = std::filesystem::space(tmp, error);
  if (error)
    throw FileError(tmp.string(), std::nullopt, "cannot tell its free space: " + error.message());
  return std::max<uint64_t>(space.available / 10 * 9, 1);
}

// The options that need no file: a usage error before anything is read.
void checkOptions(Options& o) {
  o.build.fit = named(kFitNames, o.fit, "--fit");
  o.build.orient = named(kOrientNames, o.orient, "--orient");
  o.build.removeOutliers = !o.keepOutliers;
  if (!o.bakeLight.empty()) o.build.lighting = lightBakeFromScene(o.bakeLight, o.bounces, o.bakeRays);
  validateOptions(o.build);  // before any file is read
  if (o.threads < 0) throw UsageError("--threads must be 0 (all cores) or more");
  if (!o.texture.empty()) {
    o.build.texture.at = named(kTextureAtNames, o.textureAt, "--texture-at");
    o.build.texture.image = o.texture;
  }
  memoryBudget(o.memory);
  if (o.chunkPoints && *o.chunkPoints == 0) throw UsageError("--chunk-points must be 1 or more");
  if (o.maxTemp != "auto") parseSize(o.maxTemp, "--max-temp");
  const std::string& scalar = o.build.keepScalar;
  if (!scalar.empty() && !o.build.keepPoints && o.volumePoints.empty())
    throw UsageError("--keep-scalar keeps a value with the kept points (--keep-points) or the "
                     "volume points (--volume-points): give one of them");
  if (scalar.size() > kMaxValueNameBytes)
    throw UsageError("--keep-scalar: a name of at most 32 bytes, not '" + scalar + "'");
  if (scalar == "density" && !o.volumePoints.empty())
    throw UsageError("--keep-scalar density is the scan's point density: the volume points "
                     "(--volume-points) need a value their file carries");
  if (!o.volumePoints.empty() && scalar.empty())
    throw UsageError("--volume-points needs --keep-scalar NAME: the value of the volume's "
                     "points in " + o.volumePoints);
}

// --volume-points FILE: its points and the value --keep-scalar names, read before the scan.
PointCloud readVolumePoints(const Options& o, const std::vector<std::filesystem::path>& scan) {
  const std::filesystem::path path(o.volumePoints);
  refuseOutputOverInput(o.output, path, "-o");
  for (const auto& file : scan)
    if (namesSameFile(file, path))
      throw UsageError("--volume-points " + o.volumePoints +
                       " is also a scan input: volume points are never part of the surface");
  ReadOptions read;
  read.columns = o.volumeColumns;
  LoadedPoints loaded;
  try {
    loaded = loadPoints({path}, read, nullptr, o.build.keepScalar);
  } catch (const FileError& error) {
    // A text file names its value columns: say how.
    if (!o.volumeColumns.empty() || error.reason().find("has no scalar") == std::string::npos)
      throw;
    throw FileError(error.file(), error.offset(),
                    error.reason() + "; a text file names its columns with --volume-columns, "
                                     "e.g. x,y,z," + o.build.keepScalar);
  }
  if (loaded.cloud.size() == 0)
    throw FileError(path, std::nullopt, "has no points (--volume-points)");
  return std::move(loaded.cloud);
}

// The outputs (-o, --report), checked against the inputs before any work; the input files.
std::vector<std::filesystem::path> checkPaths(const Options& o) {
  const std::filesystem::path output(o.output);
  checkOutputPath(output, "-o", o.force);
  if (!o.report.empty()) {
    checkOutputPath(o.report, "--report", true);  // a report is replaced, as a log is
    if (namesSameFile(o.report, output))
      throw UsageError("-o and --report name the same file: " + o.report);
  }
  const std::vector<std::filesystem::path> files = expandInputs(o.inputs);
  for (const auto& file : files) {
    refuseOutputOverInput(output, file, "-o");
    if (!o.report.empty()) refuseOutputOverInput(o.report, file, "--report");
  }
  if (!o.writeStrays.empty()) {
    if (o.keepOutliers)
      throw UsageError("--write-strays has nothing to write with --keep-outliers");
    checkOutputPath(o.writeStrays, "--write-strays", true);
    if (namesSameFile(o.writeStrays, output) ||
        (!o.report.empty() && namesSameFile(o.writeStrays, o.report)))
      throw UsageError("--write-strays names the same file as -o or --report: " + o.writeStrays);
    for (const auto& file : files) refuseOutputOverInput(o.writeStrays, file, "--write-strays");
  }
  if (!o.texture.empty()) checkImageReadable(o.build.texture.image);  // before the points
  return files;
}

// Where the temporary files go: --tmp (made when missing, with its parents) or the output's
// directory. Files left there by runs that were killed (kill -9, power loss) are removed.
// Not in a distributed run: the other ranks' files, on other machines, belong to processes this
// machine does not know.
std::filesystem::path temporaryDirectory(const Options& o, std::optional<MadeDirectories>& made,
                                         bool removeStale) {
  const std::filesystem::path output(o.output);
  const std::filesystem::path outputDirectory =
      output.has_parent_path() ? output.parent_path() : std::filesystem::path(".");
  const auto removeStaleTemporaries = [&](const std::filesystem::path& directory) {
    return removeStale ? iso::removeStaleTemporaries(directory) : size_t{0};
  };
  size_t stale = removeStaleTemporaries(outputDirectory);
  std::filesystem::path tmp = outputDirectory;
  if (!o.tmp.empty()) {
    made.emplace(o.tmp, "--tmp");
    if (::access(o.tmp.c_str(), W_OK | X_OK) != 0)
      throw FileError(
          o.tmp, std::nullopt,
          std::string("cannot write temporary files there (--tmp): ") + std::strerror(errno));
    tmp = o.tmp;
    std::error_code error;
    if (!std::filesystem::equivalent(tmp, outputDirectory, error))
      stale += removeStaleTemporaries(tmp);
  }
  if (stale > 0 && !o.quiet)
    fmt::print(stderr, "note: removed {} temporary file{} of an interrupted earlier run\n", stale,
               stale == 1 ? "" : "s");
  return tmp;
}

// What a conversion's results depend on, for --resume: the version, every file it reads (path,
// size, time of last change) and every option that changes what it computes.
std::string fingerprint(const Options& o, const std::vector<std::filesystem::path>& files) {
  const auto identity = [](const std::filesystem::path& file) {
    std::error_code error;
    const std::filesystem::path path = std::filesystem::weakly_canonical(file, error);
    const auto changed = std::filesystem::last_write_time(file, error).time_since_epoch().count();
    return nlohmann::json{{"file", (error ? file : path).string()},
                          {"bytes", std::filesystem::is_regular_file(file, error)
                                        ? std::filesystem::file_size(file, error)
                                        : 0},
                          {"changed", changed}};
  };
  nlohmann::json f{{"version", ISO_VERSION},
                   {"options", optionsJson(o.build)},
                   {"columns", o.columns},
                   {"strays_kept", !o.writeStrays.empty()}};
  for (const auto& file : files) f["inputs"].push_back(identity(file));
  for (const std::string& more : {o.texture, o.volumePoints, o.bakeLight})
    if (!more.empty()) f["also"].push_back(identity(more));
  return f.dump();
}

// Where --resume keeps its checkpoints: ".NAME.resume" beside the temporary files.
std::filesystem::path resumeDirectory(const Options& o, const std::filesystem::path& tmp) {
  return tmp / ("." + std::filesystem::path(o.output).filename().string() + ".resume");
}

// What Ctrl-C leaves at each stage, said when it comes (tools/iso/interrupt.h).
std::function<void(const std::string&)> interruptMessages(const Options& o, ProgressMode mode,
                                                          const MadeDirectories* made,
                                                          const std::filesystem::path& state) {
  const std::string left = std::filesystem::exists(o.output) ? o.output + " keeps what it held"
                                                             : std::string("nothing was written");
  std::string removed = "temporary files removed";
  if (made != nullptr && !made->made().empty())
    removed += ", with the directory " + made->made().front().string() + " made for them";
  if (!state.empty())
    removed += "; the stages done are kept in " + state.string() + " (run again with --resume)";
  const bool live = mode == ProgressMode::Line;
  return [=](const std::string& stage) {
    const std::string when = stage.empty()     ? "before reading the points"
                             : stage == "read" ? "while reading the points"
                                               : "in the " + stage + " stage";
    setInterruptMessage("iso convert: interrupted " + when + "; " + left + ", " + removed, live);
  };
}

// One conversion; `mpi` when this process is one of a distributed run's ranks.
int runConversion(Options& o, const MpiRanks* mpi) {
  const bool worker = mpi != nullptr && mpi->rank() != 0;
  if (worker) {  // rank 0 speaks for the run
    o.quiet = true;
    o.progress = "none";
  }
  if (mpi != nullptr && o.resume)
    throw UsageError("--resume keeps one process's state: it cannot be used with " +
                     std::to_string(mpi->count()) + " ranks (mpirun)");
  checkOptions(o);
  const ProgressMode mode =
      o.progress == "auto"
          ? (isatty(fileno(stderr)) && !o.quiet ? ProgressMode::Line : ProgressMode::None)
          : named(kProgressNames, o.progress, "--progress", "auto, ");
  const std::vector<std::filesystem::path> files = checkPaths(o);
  const std::filesystem::path output(o.output);
  std::optional<MadeDirectories> made;
  const std::filesystem::path tmp = temporaryDirectory(o, made, mpi == nullptr);
  std::optional<ResumeState> state;
  if (o.resume) state.emplace(resumeDirectory(o, tmp), fingerprint(o, files));
  const auto interrupted = interruptMessages(o, mode, made && !state ? &*made : nullptr,
                                             state ? state->directory() : "");
  interrupted("");
  std::optional<tbb::global_control> threads;
  if (o.threads > 0)
    threads.emplace(tbb::global_control::max_allowed_parallelism, size_t(o.threads));
  ProgressReporter progress(mode);
  progress.observeStages(interrupted);
  const uint64_t memory = memoryBudget(o.memory);
  TemporaryDiskLimit temporaryLimit(temporaryDiskLimit(o.maxTemp, tmp));
  // The points go to disk as they are read (each file is parsed once); the point stages then
  // run chunk by chunk.
  // The ranks' results go to rank 0's directory, and the other ranks keep their files in it.
  std::optional<SpillDirectory> directory;
  std::optional<Ranks> ranks;
  if (!worker) directory.emplace(tmp);
  if (mpi != nullptr) ranks = mpi->ranks(worker ? "" : directory->path());
  if (worker) directory.emplace(ranks->shared, "rank-" + std::to_string(ranks->rank));
  SpillDirectory& spill = *directory;
  std::unique_ptr<RawSpill> raw;
  const PointCloud volume =
      o.volumePoints.empty() ? PointCloud{} : readVolumePoints(o, files);
  ReadOptions read;
  read.columns = o.columns;
  // The scan's own scalar, when the kept points keep one it carries. With --volume-points the
  // scalar is the volume's: the kept points keep it only where every scan file has it.
  std::string scalar =
      o.build.keepPoints && o.build.keepScalar != "density" ? o.build.keepScalar : "";
  if (!scalar.empty() && !o.volumePoints.empty() && !everyFileHas(files, read, scalar)) {
    if (!o.quiet)
      fmt::print(stderr, "note: the kept points keep no '{}': not every scan file has it\n",
                 scalar);
    scalar.clear();
    o.build.keepScalar.clear();
  }
  keepLargeBlocksOutOfTheHeap();  // the reader's buffers too (pipeline/base/buffers.h)
  const ReadSummary loaded = readPoints(
      files, read, &progress,
      [&](bool normals, bool colors) {
        raw = std::make_unique<RawSpill>(spill, PointLayout{normals, colors, scalar});
      },
      [&](const PointCloud& batch) { raw->append(batch); }, scalar);
  raw->finish();
  if (!o.quiet && mode != ProgressMode::Json) {
    fmt::print(stderr, "read {} points from {} file{} in {:.2f} s\n", withSeparators(raw->size()),
               files.size(), files.size() == 1 ? "" : "s", loaded.seconds);
    for (const std::string& note : loaded.notes) fmt::print(stderr, "note: {}\n", note);
  }
  reportCoordinateSystem(coordinateSystemOf(loaded.inputs), o.quiet || mode == ProgressMode::Json);
  if (worker) {
    prepareAsRank(*raw, spill, outOfCoreBudget(o, memory), o.build, *ranks, !o.writeStrays.empty());
    return kExitOk;
  }
  // An octree run of all points (not chunk jobs) keeps its work lists in memory (specs/pipeline.md
  // §15): about 5 bytes per point. Say so before a long run when that alone exceeds the budget.
  const uint64_t listBytes = raw->size() * 5;
  if (raw->size() <= o.build.octreeChunkPoints && listBytes > memory && !o.quiet &&
      mode != ProgressMode::Json)
    fmt::print(stderr,
               "note: the octree stages' work lists stay in memory: about {} for {} points, "
               "more than --memory {}\n",
               byteSize(listBytes), withSeparators(raw->size()), byteSize(memory));
  ConvertSource source{loaded.inputs,
                       loaded.seconds,
                       loaded.nonFiniteDropped,
                       {},
                       &progress,
                       {},
                       o.volumePoints.empty() ? nullptr : &volume};
  if (!o.quiet && mode == ProgressMode::None)
    source.onStage = [](const std::string& stage, double seconds) {
      if (stage != "read") fmt::print(stderr, "  {:<16} {:.3f} s\n", stage, seconds);
    };
  source.resume = state ? &*state : nullptr;
  source.ranks = ranks ? &*ranks : nullptr;
  PointCloud strays;
  if (!o.writeStrays.empty())
    source.onStrays = [&](PointCloud removed) { strays = std::move(removed); };
  nlohmann::json report;
  try {
    report = convertSpilled(*raw, spill, outOfCoreBudget(o, memory), output, o.build, source);
  } catch (const ConvertError& error) {
    std::string names;
    for (const auto& file : files) names += (names.empty() ? "" : ", ") + file.string();
    throw FileError(names, std::nullopt, error.what());
  }
  if (state) {
    if (!o.quiet)
      for (const std::string& note : state->notes()) fmt::print(stderr, "note: {}\n", note);
    state->finish();
  }
  setInterruptMessage("iso convert: interrupted after writing " + o.output);
  if (!o.report.empty()) writeTextFile(o.report, report.dump(2) + "\n");
  if (!o.writeStrays.empty()) writePly(o.writeStrays, strays);
  if (o.json)
    fmt::print("{}\n", report.dump(2));
  else
    printReport(report, o);
  return kExitOk;
}

// A run under an MPI launcher is one rank of a distributed conversion: an error on any rank ends
// them all (the others would wait for it).
int run(Options& o) {
  if (launchedRanks() <= 1) return runConversion(o, nullptr);
  MpiRanks mpi;
  try {
    return runConversion(o, &mpi);
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso convert (rank {} of {}): {}\n", mpi.rank(), mpi.count(), error.what());
    mpi.abort(dynamic_cast<const UsageError*>(&error) ? kExitUsage : kExitFailure);
  }
}

}  // namespace

void addConvertCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<Options>();
  CLI::App* c = app.add_subcommand(
      "convert",
      "Convert point files (PLY, LAS, LAZ, E57, PCD, Draco, text: XYZ/TXT/PTS/CSV/ASC/NEU/XYZRGB "
      "or any name with --columns; .gz too) into an .iso file");
  c->footer(
      "Inputs: PLY, LAS 1.0-1.4 (point formats 0-10), LAZ (LASzip-compressed LAS, point formats "
      "0-3 and 6-8, decoded by laz-perf on every core), E57 (every scan, its pose applied), PCD, "
      "Draco .drc and text, each but LAZ and E57 also gzip-compressed (.gz); text of another "
      "extension is read when its lines are numbers, or always with --columns. Files and "
      "directories mix freely. The coordinate system of LAS and LAZ inputs (OGC WKT, EPSG code of "
      "GeoTIFF keys) is kept in the file's metadata and shown by `iso info`.");
  c->add_option("inputs", o->inputs, "Point files or directories of them")->required();
  c->add_option("-o,--output", o->output,
                "The .iso file to write (its directory must exist); Ctrl-C stops the conversion "
                "with a line saying what it left, removing its temporary files")
      ->required();
  c->add_flag("-f,--force", o->force, "Replace the output file if it exists");
  c->add_option("--columns", o->columns,
                "Column spec of text inputs, e.g. x,y,z,nx,ny,nz,r,g,b (_ skips); with it, an "
                "input of any extension that is not PLY, LAS, LAZ, E57, Draco or PCD is read as "
                "text (without it: guessed from the first lines)");
  c->add_option("--neighbors", o->build.neighbors,
                "k of the k-nearest-neighbour radius of influence")
      ->capture_default_str();
  c->add_option("--smoothing", o->build.smoothing,
                "Scale of the radii of influence (σ = smoothing · r)")
      ->capture_default_str();
  c->add_option("--fit", o->fit, "Local surface fitted at corners: sphere or plane")
      ->capture_default_str();
  c->add_option("--orient", o->orient, "Orientation of estimated normals: auto, up or propagate")
      ->capture_default_str();
  c->add_option("--leaf-points", o->build.leafPoints, "Nodes with more points may be subdivided")
      ->capture_default_str();
  c->add_option("--max-depth", o->build.maxDepth, "Deepest octree level (1 to 20)")
      ->capture_default_str();
  c->add_option("--tolerance", o->build.tolerance, "Allowed patch error, in point spacings")
      ->capture_default_str();
  c->add_option("--corner-fit", o->build.cornerFit,
                "Passes moving leaf corners so that the surface runs through the points (0: the "
                "sampled signed distances, whose trilinear patches shrink convex parts; "
                "specs/pipeline.md §6)")
      ->capture_default_str();
  c->add_flag("--fill-holes", o->build.fillHoles,
              "Keep the surface the patches make across holes in the scan (a closed surface); "
              "without it the surface ends where the points end: a leaf without points whose surface "
              "lies mostly farther than --trim-reach radii of influence from every point is left "
              "out");
  c->add_option("--trim-reach", o->build.trimReach,
                "How far from the points, in radii of influence, the surface may reach before it "
                "is trimmed")
      ->capture_default_str()
      ->check(CLI::Range(0.5, 100.0));
  c->add_option("--normal-bits", o->build.normalBits,
                "Octahedral normal bits per component: 8 or 12")
      ->capture_default_str();
  c->add_option("--chunk-nodes", o->build.chunkNodes, "Octree nodes per file chunk, about")
      ->capture_default_str();
  c->add_option("--zstd-level", o->build.zstdLevel, "zstd compression level of chunks")
      ->capture_default_str();
  c->add_flag(
      "--keep-outliers", o->keepOutliers,
      "Keep stray points (isolated, in small separate groups, or far sparser than the scan) "
      "instead of removing them");
  c->add_option("--write-strays", o->writeStrays,
                "Write the points removed as strays to this PLY file (world coordinates, with "
                "their normals and colors), to look at what was left out");
  c->add_option("--stray-group", o->build.strayGroupPoints,
                "Separate groups of fewer points are strays (birds, multipath, dust)")
      ->capture_default_str()
      ->check(CLI::Range(1u, 1000000000u));
  CLI::Option* texture = c->add_option(
      "--texture", o->texture,
      "An image (any OpenImageIO reads; PNG or PPM in builds without it) projected along the three "
      "axes and blended by the "
      "normal, baked into the colors (times the points' own colors when they have some)");
  c->add_option("--texture-scale", o->build.texture.scale,
                "World units one repeat of the texture spans (default: the frame's size)")
      ->needs(texture);
  c->add_option("--texture-sharpness", o->build.texture.sharpness,
                "P of the blend weights |n·axis|^P: higher gives sharper seams")
      ->capture_default_str()
      ->needs(texture);
  c->add_option("--texture-at", o->textureAt,
                "Sample the texture at the points or at the corners' projections")
      ->capture_default_str()
      ->needs(texture);
  CLI::Option* ao = c->add_flag("--bake-ao", o->build.occlusion.enabled,
                                "Trace ambient occlusion against the surface and store it at "
                                "every corner");
  c->add_option("--ao-rays", o->build.occlusion.rays, "Rays per corner for --bake-ao")
      ->capture_default_str()
      ->needs(ao);
  c->add_option("--ao-radius", o->build.occlusion.radius,
                "How far (world units) an occluder counts (default: a tenth of the frame)")
      ->needs(ao);
  CLI::Option* light = c->add_option(
      "--bake-light", o->bakeLight,
      "Bake this scene file's lights into the file (light maps: irradiance at every corner, "
      "shadows and diffuse bounces; as `iso bake` does)");
  light->check(CLI::ExistingFile);
  addLightBakeOptions(c, o->bounces, o->bakeRays, light);
  CLI::Option* keep = c->add_flag(
      "--keep-points", o->build.keepPoints,
      "Also store the input points in the file (Draco-compressed, a cell per chunk), for `iso "
      "export --points`");
  c->add_option("--point-bits", o->build.pointBits,
                "Position precision of --keep-points: 2^-N of the frame's size")
      ->capture_default_str()
      ->needs(keep);
  c->add_option("--keep-scalar", o->build.keepScalar,
                "A value kept per point with --keep-points and --volume-points (16-bit codes; "
                "integers exact): LAS/LAZ intensity, return_number, classification, gps_time; E57 "
                "intensity; any PLY or PCD scalar property, or named text column, by name; or "
                "density (the scan's local point density, points per square unit)");
  c->add_option("--volume-points", o->volumePoints,
                "A point file of volume samples (a simulation's or a sensor's values inside the "
                "scanned object), stored beside the surface with their --keep-scalar value and "
                "never used to build it; drawn by `iso view --draw pss --volume NAME`");
  c->add_option("--volume-columns", o->volumeColumns,
                "Column spec of a text --volume-points file, e.g. x,y,z,value");
  c->add_option("--threads", o->threads, "Worker threads (0: all cores); the output is the same")
      ->capture_default_str();
  c->add_option("--progress", o->progress,
                "Progress on stderr: auto (a live line on a terminal), line, json (one object per "
                "update) or none")
      ->capture_default_str();
  c->add_option("--memory", o->memory,
                fmt::format("Memory budget (e.g. 2G, 512M; units K, M, G, T are powers of 1024; "
                            "auto: half the RAM), at least {}M, the smallest a conversion keeps "
                            "to: the point stages run in chunks that fit it, and the large arrays "
                            "live in temporary files whose pages are dropped when the process "
                            "nears it; the output does not depend on it",
                            OutOfCoreBudget::kSmallestMemory >> 20))
      ->capture_default_str();
  c->add_option("--chunk-points", o->chunkPoints,
                "Points a chunk of the point stages holds at most, besides its halo (default: "
                "--memory / 600; at least --orient-block-points); the output does not depend on "
                "it");
  c->add_option("--tmp", o->tmp,
                "Directory for temporary files (default: the output's; made with its parents "
                "when missing): the points as read, sorted, and their arrays; all removed "
                "afterwards, with the directories made for them");
  c->add_flag("--resume", o->resume,
              "Keep the stages done in .NAME.resume beside the temporary files (each finished chunk "
              "of the point stages and chunk job of the octree stages, and checkpoints as the "
              "point stages and the corner stage end), so that a run killed or stopped and started "
              "again with --resume goes on from the last one; the same bytes as a run that went "
              "through. The state is removed when the file is written");
  c->add_option("--max-temp", o->maxTemp,
                "Most temporary disk the conversion may use (e.g. 20G; auto: 90 % of the free "
                "space in --tmp); it stops with an error, removing its files, before going past")
      ->capture_default_str();
  c->add_option("--orient-block-points", o->build.orientBlockPoints,
                "Points per block of normal orientation (a parameter of the result)")
      ->capture_default_str();
  c->add_option("--octree-chunk-points", o->build.octreeChunkPoints,
                "Points a chunk job of the octree stages owns, about: larger inputs run those "
                "stages chunk by chunk, each with a halo (a parameter of the result)")
      ->capture_default_str();
  c->add_option("--report", o->report,
                "Also write the report (with stage times and memory) as JSON to this file");
  c->add_flag("--json", o->json, "Print the report as JSON");
  c->add_flag("-q,--quiet", o->quiet, "No progress on stderr");
  c->callback([o, &exitCode] { exitCode = runGuarded("convert", [&] { return run(*o); }); });
}

}  // namespace iso::cli
