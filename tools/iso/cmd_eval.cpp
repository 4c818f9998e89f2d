// `iso eval FILE.iso --shape NAME | --mesh FILE.ply | --points INPUT...`: accuracy as JSON.
#include <fmt/core.h>

#include "commands.h"
#include "evaluate.h"
#include "inputs.h"
#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "shape_options.h"

namespace iso::cli {
namespace {

struct Options {
  std::string file;
  std::string shape;
  std::vector<std::string> points;
  std::string against;  // --against B.iso
  bool perLevel = false;
  std::string columns;
  ShapeOptions truth;
  EvalOptions eval;
  double spacing = 0.0;
};

// The mean point spacing of the file's input, from its conversion report.
double reportedSpacing(const Reader& reader) {
  const nlohmann::json metadata = nlohmann::json::parse(reader.metadata(), nullptr, false);
  if (metadata.is_object() && metadata.contains("report") &&
      metadata["report"].contains("mean_spacing"))
    return metadata["report"]["mean_spacing"].get<double>();
  return 0.0;
}

int run(Options& o) {
  const int truths = int(!o.shape.empty()) + int(!o.truth.mesh.empty()) + int(!o.points.empty()) +
                     int(!o.against.empty());
  if (truths != 1)
    throw std::invalid_argument(
        "give exactly one of --shape NAME, --mesh FILE.ply, --points FILE..., --against B.iso");
  if (o.perLevel && o.points.empty())
    throw std::invalid_argument("--per-level measures against --points");
  const Reader reader = Reader::open(o.file);
  const SurfaceModel surface = SurfaceModel::load(reader);
  nlohmann::json result;
  if (!o.points.empty()) {
    ReadOptions read;
    read.columns = o.columns;
    const PointCloud cloud = loadPoints(expandInputs(o.points), read).cloud;
    result = evaluateAgainstPoints(surface, cloud);
    if (o.perLevel) result["levels"] = evaluateLevels(reader, cloud);
  } else if (!o.against.empty()) {
    const Reader other = Reader::open(o.against);
    result = evaluateAgainstFile(surface, SurfaceModel::load(other));
    result["against"] = o.against;
    const double spacing = reportedSpacing(reader);
    if (spacing > 0.0) {
      result["mean_spacing"] = spacing;
      result["rms_over_spacing"] = result["rms"].get<double>() / spacing;
      result["max_over_spacing"] = result["max"].get<double>() / spacing;
    }
  } else {
    const double spacing = o.spacing > 0.0 ? o.spacing : reportedSpacing(reader);
    if (!(spacing > 0.0))
      throw FileError(o.file, std::nullopt, "has no reported mean spacing; give --spacing");
    if (!o.shape.empty()) o.truth.params.name = o.shape;
    o.eval.orientedNormals = o.truth.mesh.empty();
    result = evaluateAgainstShape(surface, *makeTruth(o.truth), spacing, o.eval);
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
  c->add_flag("--per-level", o->perLevel,
              "With --points: the error of every level-of-detail cut, coarsest first");
  c->add_option("--columns", o->columns, "Column spec of text point files");
  c->add_option("--spacing", o->spacing,
                "Mean point spacing (default: the file's conversion report)");
  c->add_option("--rays", o->eval.rays, "Rays for the hole rate")->capture_default_str();
  c->add_option("--samples", o->eval.truthSamples, "Samples of the truth")->capture_default_str();
  c->add_option("--seed", o->eval.seed, "Random seed")->capture_default_str();
  addShapeOptions(*c, o->truth);
  c->callback([o, &exitCode] { exitCode = runWithUsageErrors("eval", [&] { return run(*o); }); });
}

}  // namespace iso::cli
