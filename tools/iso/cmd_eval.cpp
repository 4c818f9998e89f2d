// `iso eval FILE.iso --shape NAME | --mesh FILE.ply | --points INPUT... | --against B.iso |
// --tiles DIR`, and
// `--visibility`: accuracy, and what the viewer shows of the scan, as JSON.
#include <fmt/core.h>

#include <algorithm>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/against_pss.h"
#include "pipeline/analysis/evaluate.h"
#include "pipeline/analysis/measure.h"
#include "pipeline/analysis/tiles.h"
#include "pipeline/analysis/visibility.h"
#include "pipeline/base/files.h"
#include "pipeline/base/options.h"
#include "base/image.h"
#include "pipeline/io/ply.h"
#include "pipeline/output/keep_points.h"
#include "pipeline/points/points.h"
#include "tools/iso/commands.h"
#include "tools/iso/inputs.h"
#include "tools/iso/interrupt.h"
#include "tools/iso/shape_options.h"

namespace iso::cli {
namespace {

struct Options {
  std::string file;
  std::string shape;
  std::vector<std::string> points;
  std::string against;  // --against B.iso
  std::string tiles;    // --tiles DIR
  int depth = -1;       // --depth D
  bool perLevel = false;
  bool visibility = false;
  uint64_t visibilityPoints = 1000000;
  std::string seenThrough;  // --seen-through OUT.ply
  bool force = false;
  VisibilityOptions view;
  std::string columns;
  ShapeOptions truth;
  EvalOptions eval;
  double spacing = 0.0;
  bool keepOutliers = false;  // --keep-outliers: measure the strays too
  bool againstPss = false;    // --against-pss
  std::string pictures;       // --pictures DIR
  AgainstPssOptions pss;
};

// The points measured, without the strays the conversion removed (found again by its rule and
// parameters, unless it kept them or --keep-outliers is given); the count left out in `result`.
PointCloud measuredPoints(PointCloud cloud, const Reader& reader, const Options& o,
                          nlohmann::json& result) {
  const nlohmann::json metadata = nlohmann::json::parse(reader.metadata(), nullptr, false);
  const nlohmann::json parameters =
      metadata.is_object() && metadata.contains("parameters") && metadata["parameters"].is_object()
          ? metadata["parameters"]
          : nlohmann::json::object();
  const BuildOptions defaults;
  const auto number = [&](const char* key, auto fallback) {
    return parameters.contains(key) && parameters[key].is_number_unsigned()
               ? parameters[key].get<decltype(fallback)>()
               : fallback;
  };
  const bool removed =
      !(parameters.contains("remove_outliers") && parameters["remove_outliers"].is_boolean() &&
        !parameters["remove_outliers"].get<bool>());
  result["strays_left_out"] = 0;
  if (o.keepOutliers || !removed) return cloud;
  const int k = std::clamp(number("neighbors", defaults.neighbors), 1, 1000);
  const uint32_t group = std::max(number("stray_group_points", defaults.strayGroupPoints), 1u);
  PointCloud kept = withoutStrays(cloud, k, group);
  result["strays_left_out"] = cloud.size() - kept.size();
  return kept;
}

// The point spacing of the file's input, from its conversion report (files written before the
// spacing became a median name the mean).
double reportedSpacing(const Reader& reader) {
  const nlohmann::json metadata = nlohmann::json::parse(reader.metadata(), nullptr, false);
  if (!metadata.is_object() || !metadata.contains("report")) return 0.0;
  for (const char* key : {"spacing", "mean_spacing"})
    if (metadata["report"].contains(key) && metadata["report"][key].is_number())
      return metadata["report"][key].get<double>();
  return 0.0;
}

// The file's kept points (`iso convert --keep-points`) without their strays, every step-th up to
// `limit`.
std::vector<glm::dvec3> keptPoints(const Reader& reader, uint64_t limit, const Options& o,
                                   nlohmann::json& result) {
  const KeptPointsInfo info = keptPointsInfo(reader);
  if (info.points == 0)
    throw FileError(reader.name(), std::nullopt,
                    "keeps no points (convert it with --keep-points); give --points INPUT");
  PointCloud all;
  forEachKeptPoints(reader, [&](const PointCloud& chunk) {
    all.positions.insert(all.positions.end(), chunk.positions.begin(), chunk.positions.end());
  });
  return samplePoints(measuredPoints(std::move(all), reader, o, result),
                      limit == 0 ? ~uint64_t{0} : limit);
}

// What the viewer shows of the points (`--visibility`), through its own tracer; the points seen
// through written to --seen-through.
nlohmann::json visibilityOf(const Reader& reader, std::span<const glm::dvec3> points,
                            double spacing, const Options& o) {
  const Visibility v = measureVisibility(reader, points, spacing, o.view);
  nlohmann::json out = v.json();
  if (!o.seenThrough.empty()) {
    PointCloud seen;
    for (const uint32_t i : v.seen) seen.positions.push_back(points[i]);
    writePly(o.seenThrough, seen, {.comments = {"points of " + o.file + " seen through"}});
    out["seen_through_file"] = o.seenThrough;
  }
  return out;
}

int run(Options& o) {
  const int truths = int(!o.shape.empty()) + int(!o.truth.mesh.empty()) + int(!o.points.empty()) +
                     int(!o.against.empty()) + int(!o.tiles.empty()) + int(o.againstPss);
  if (truths != 1 && !(o.visibility && truths == 0))
    throw UsageError(
        "give exactly one of --shape NAME, --mesh FILE.ply, --points FILE..., --against B.iso, "
        "--tiles DIR, --against-pss "
        "(or --visibility alone, on the file's kept points)");
  if (o.againstPss && o.visibility) throw UsageError("--visibility does not go with --against-pss");
  if (!o.pictures.empty() && !o.againstPss) throw UsageError("--pictures goes with --against-pss");
  if (o.pss.size < 16 || o.pss.size > 4096) throw UsageError("--size: 16 to 4096 pixels");
  if (o.perLevel && o.points.empty()) throw UsageError("--per-level measures against --points");
  if (o.depth != -1 && o.tiles.empty()) throw UsageError("--depth picks a cut of --tiles");
  if (o.visibility && !o.tiles.empty())
    throw UsageError("--visibility measures --points or the file's kept points");
  if (o.visibility && !o.against.empty())
    throw UsageError("--visibility measures --points or the file's kept points");
  o.view.seed = o.eval.seed;
  if (!o.seenThrough.empty()) {
    if (!o.visibility) throw UsageError("--seen-through needs --visibility");
    checkOutputPath(o.seenThrough, "--seen-through", o.force);
    for (const std::string& input : o.points)
      refuseOutputOverInput(o.seenThrough, input, "--seen-through");
    refuseOutputOverInput(o.seenThrough, o.file, "--seen-through");
    setInterruptMessage("iso eval: interrupted; nothing was written");
  }
  const Reader reader = Reader::open(o.file);
  nlohmann::json result;
  if (o.visibility && truths == 0) {
    const double spacing = o.spacing > 0.0 ? o.spacing : reportedSpacing(reader);
    if (!(spacing > 0.0))
      throw FileError(o.file, std::nullopt, "has no reported spacing; give --spacing");
    result["visibility"] =
        visibilityOf(reader, keptPoints(reader, o.visibilityPoints, o, result), spacing, o);
    result["spacing"] = spacing;
    result["file"] = o.file;
    fmt::print("{}\n", result.dump(2));
    return kExitOk;
  }
  if (o.againstPss) {
    const double spacing = o.spacing > 0.0 ? o.spacing : reportedSpacing(reader);
    if (!(spacing > 0.0))
      throw FileError(o.file, std::nullopt, "has no reported spacing; give --spacing");
    PointCloud kept;
    forEachKeptPoints(reader, [&](const PointCloud& chunk) {
      for (size_t i = 0; i < chunk.size(); ++i) appendPoint(kept, chunk, i);
    });
    if (kept.size() == 0)
      throw FileError(o.file, std::nullopt,
                      "keeps no points to fit a point set surface to (convert with --keep-points)");
    AgainstPssOptions pss = o.pss;
    if (!o.pictures.empty()) {
      const std::filesystem::path dir(o.pictures);
      std::filesystem::create_directories(dir);
      // Per view: the ISO, the PSS, and their difference (gray: equal; red: the ISO brighter,
      // blue: the PSS brighter), as the seed ISO paper's Fig. 4.10 shows them.
      pss.pictures = [&o, dir](int view, const std::vector<uint8_t>& iso,
                         const std::vector<uint8_t>& ref) {
        const uint32_t n = uint32_t(o.pss.size);
        std::vector<uint32_t> a(iso.size()), b(iso.size()), d(iso.size());
        for (size_t i = 0; i < iso.size(); ++i) {
          const auto gray = [](uint32_t v) { return v | v << 8 | v << 16 | 0xFF000000u; };
          a[i] = gray(iso[i]);
          b[i] = gray(ref[i]);
          const int diff = 2 * (int(iso[i]) - int(ref[i]));
          const uint32_t red = uint32_t(std::clamp(128 + diff, 0, 255)),
                         green = uint32_t(std::clamp(128 - std::abs(diff), 0, 255)),
                         blue = uint32_t(std::clamp(128 - diff, 0, 255));
          d[i] = red | green << 8 | blue << 16 | 0xFF000000u;
        }
        const std::string axis[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
        writeRgba8Image(dir / ("view" + axis[view] + "-iso.png"), n, n, a);
        writeRgba8Image(dir / ("view" + axis[view] + "-pss.png"), n, n, b);
        writeRgba8Image(dir / ("view" + axis[view] + "-difference.png"), n, n, d);
      };
    }
    result = evaluateAgainstPss(reader, std::move(kept), spacing, pss);
    result["file"] = o.file;
    fmt::print("{}\n", result.dump(2));
    return kExitOk;
  }
  const SurfaceModel surface = SurfaceModel::load(reader);
  if (!o.points.empty()) {
    ReadOptions read;
    read.columns = o.columns;
    nlohmann::json strays;
    const PointCloud cloud =
        measuredPoints(loadPoints(expandInputs(o.points), read).cloud, reader, o, strays);
    result = evaluateAgainstPoints(surface, cloud);
    result["strays_left_out"] = strays["strays_left_out"];
    if (o.perLevel) result["levels"] = evaluateLevels(reader, cloud);
    if (o.visibility)
      result["visibility"] = visibilityOf(
          reader, samplePoints(cloud, o.visibilityPoints == 0 ? cloud.size() : o.visibilityPoints),
          o.spacing > 0.0 ? o.spacing : result["spacing"].get<double>(), o);
  } else if (!o.against.empty()) {
    const Reader other = Reader::open(o.against);
    result = evaluateAgainstFile(surface, SurfaceModel::load(other));
    result["against"] = o.against;
    const double spacing = reportedSpacing(reader);
    if (spacing > 0.0) {
      result["spacing"] = spacing;
      result["rms_over_spacing"] = result["rms"].get<double>() / spacing;
      result["max_over_spacing"] = result["max"].get<double>() / spacing;
    }
  } else {
    const double spacing = o.spacing > 0.0 ? o.spacing : reportedSpacing(reader);
    if (!(spacing > 0.0))
      throw FileError(o.file, std::nullopt, "has no reported spacing; give --spacing");
    if (!o.shape.empty()) o.truth.params.name = o.shape;
    o.eval.orientedNormals = o.truth.mesh.empty() && o.tiles.empty();
    if (!o.tiles.empty()) {
      TilesetCut cut = readTilesetCut(o.tiles, o.depth);
      if (cut.mesh.triangles.empty())
        throw FileError(o.tiles, std::nullopt, "has no triangles at that depth");
      nlohmann::json tiles = {{"directory", o.tiles},
                              {"depth", o.depth},
                              {"tiles", cut.tiles},
                              {"triangles", cut.mesh.triangles.size()},
                              {"geometric_error", cut.geometricError}};
      if (o.depth >= 0) {  // each tile of the cut against the finest tiles below it
        const TilesetCheck check = checkTilesetCut(o.tiles, o.depth);
        tiles["to_finest"] = {{"max", check.largest},
                              {"tiles_beyond_their_error", check.beyond},
                              {"worst_ratio_to_stated", check.worstRatio}};
      }
      result = evaluateAgainstShape(surface, *makeMeshShape(std::move(cut.mesh)), spacing, o.eval);
      result["tiles"] = tiles;
    } else {
      result = evaluateAgainstShape(surface, *makeTruth(o.truth), spacing, o.eval);
    }
    if (o.visibility)
      result["visibility"] =
          visibilityOf(reader, keptPoints(reader, o.visibilityPoints, o, result), spacing, o);
  }
  result["file"] = o.file;
  fmt::print("{}\n", result.dump(2));
  return kExitOk;
}

}  // namespace

void addEvalCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<Options>();
  CLI::App* c =
      app.add_subcommand("eval", "Measure an .iso surface against a known answer; prints JSON");
  c->add_option("file", o->file, ".iso file")->required();
  c->add_option("--shape", o->shape,
                "Analytic truth: sphere, torus, cube, plane or sheets (as iso gen)");
  c->add_option("--points", o->points,
                "Measure the distance of these points (e.g. the input) to the surface");
  c->add_option("--against", o->against,
                "Another .iso file: the distance between the two zero sets, both ways, and the "
                "color PSNR between them");
  c->add_flag("--against-pss", o->againstPss,
              "Against the point set surface of the file's kept points (exact mode): both ray "
              "traced on the CPU from the 6 views along the axes; silhouettes, depths, normals, "
              "PSNR of one shading, rays/s of each");
  c->add_option("--size", o->pss.size, "--against-pss: pixels across each view")
      ->capture_default_str();
  c->add_option("--pictures", o->pictures,
                "--against-pss: write each view's ISO, PSS and difference pictures (PNG) into "
                "this directory");
  c->add_option("--tiles", o->tiles,
                "A tileset `iso export --tiles` wrote: the distance between what it draws and the "
                "file's zero set, both ways (by default its finest tiles)");
  c->add_option("--depth", o->depth,
                "With --tiles: what the tileset draws when it refines to this depth of its tree "
                "(the root is 0; -1: the finest), and the largest geometric error those tiles "
                "state; with a depth, also each tile's distance to the finest tiles below it "
                "against the error it states")
      ->check(CLI::Range(-1, 64));
  c->add_flag("--per-level", o->perLevel,
              "With --points: the error of every level-of-detail cut, coarsest first");
  c->add_flag("--visibility", o->visibility,
              "What the viewer shows of the scan's points (its own tracer, far views along the "
              "axes and --views random ones): the share seen through (pixel and 8 neighbours "
              "empty) per view, and the depth error of the surface at the nearest points, in "
              "spacings. Points: --points, or the file's kept points");
  c->add_option("--seen-through", o->seenThrough,
                "With --visibility: write the points seen through in some view here (PLY), to "
                "look at where the surface is missing");
  c->add_flag("-f,--force", o->force, "Replace the --seen-through file if it exists");
  c->add_option("--views", o->view.randomViews, "Random views besides the 6 along the axes")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000));
  c->add_option("--pixel", o->view.pixelSpacings, "Pixel width in point spacings")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 1000.0));
  c->add_option("--visibility-points", o->visibilityPoints,
                "Points measured at most (every k-th; 0: all)")
      ->capture_default_str();
  c->add_option("--columns", o->columns,
                "Column spec of text point files, as for `iso convert` (with it, an input of any "
                "extension that is not PLY, LAS, LAZ, E57, Draco or PCD is read as text)");
  c->add_flag("--keep-outliers", o->keepOutliers,
              "Measure every point: by default the strays the conversion removed (found again "
              "by its rule, specs/pipeline.md §2) are left out and counted (strays_left_out)");
  c->add_option("--spacing", o->spacing, "Point spacing (default: the file's conversion report)");
  c->add_option("--rays", o->eval.rays, "Rays for the hole rate")->capture_default_str();
  c->add_option("--samples", o->eval.truthSamples, "Samples of the truth")->capture_default_str();
  c->add_option("--seed", o->eval.seed, "Random seed (samples, rays, views)")
      ->capture_default_str();
  addShapeOptions(*c, o->truth);
  c->callback([o, &exitCode] { exitCode = runGuarded("eval", [&] { return run(*o); }); });
}

}  // namespace iso::cli
