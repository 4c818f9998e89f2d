// `iso gen SHAPE -o OUT.ply|OUT.las`: a synthetic scan with a known answer.
#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "iso/error.h"
#include "pipeline/base/files.h"
#include "pipeline/geom/generate.h"
#include "pipeline/io/las.h"
#include "pipeline/io/ply.h"
#include "tools/iso/commands.h"
#include "tools/iso/interrupt.h"
#include "tools/iso/shape_options.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

struct Options {
  std::string shape;
  std::string output;
  ShapeOptions truth;
  GenerateOptions generate;
  bool noNormals = false, ascii = false, force = false;
};

int run(Options& o) {
  if (o.shape.empty() == o.truth.mesh.empty())
    throw UsageError("name one shape (sphere, torus, cube, plane, sheets) or give --mesh FILE.ply");
  checkOutputPath(o.output, "-o", o.force);
  std::string extension = std::filesystem::path(o.output).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  const bool las = extension == ".las";
  if (!las && extension != ".ply")
    throw UsageError(
        fmt::format("-o {}: write .ply or .las (the format follows the extension)", o.output));
  if (las && o.ascii) throw UsageError("--ascii is for PLY output; LAS is binary");
  if (!o.truth.mesh.empty()) refuseOutputOverInput(o.output, o.truth.mesh, "-o");
  setInterruptMessage("iso gen: interrupted; nothing was written");
  if (o.truth.mesh.empty()) o.truth.params.name = o.shape;
  ShapeOptions placed = o.truth;
  placed.offset = "0,0,0";  // generateScan adds the offset itself
  const std::unique_ptr<Shape> shape = makeTruth(placed);
  o.generate.offset = parseVector(o.truth.offset, "--offset");
  o.generate.normals = !o.noNormals && !las;
  const PointCloud points = generateScan(*shape, o.generate);
  PlyWriteOptions write;
  write.binary = !o.ascii;
  write.comments = {fmt::format(
      "iso gen {}: {} points, noise {} spacings, density ratio {}, seed {}", shape->name(),
      o.generate.count, o.generate.noise, o.generate.densityRatio, o.generate.seed)};
  if (las)
    writeLas(o.output, points);
  else
    writePly(o.output, points, write);
  fmt::print("{}: {} points of a {} (area {:.6g}, expected spacing {:.6g}){}\n", o.output,
             withSeparators(points.size()), shape->name(), shape->area(),
             expectedSpacing(shape->area(), o.generate.count),
             las && !o.noNormals ? "; LAS 1.2 holds no normals" : "");
  return kExitOk;
}

}  // namespace

void addGenCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<Options>();
  CLI::App* c = app.add_subcommand(
      "gen", "Write a synthetic scan with a known answer (PLY, or LAS by the extension)");
  c->add_option("shape", o->shape, "sphere, torus, cube, plane or sheets (or --mesh)");
  c->add_option("-o,--output", o->output, "The file to write: .ply, or .las (LAS 1.2, no normals)")
      ->required();
  c->add_option("-n,--count", o->generate.count, "Number of points (1 to 2^32)")
      ->capture_default_str()
      ->check(CLI::Range(uint64_t{1}, uint64_t{1} << 32));
  c->add_option("--noise", o->generate.noise, "Noise along the normal, in point spacings (σ)")
      ->capture_default_str();
  c->add_option("--density-ratio", o->generate.densityRatio, "Densest to sparsest sampling along x")
      ->capture_default_str();
  c->add_option("--seed", o->generate.seed, "Random seed")->capture_default_str();
  c->add_flag("--no-normals", o->noNormals, "Leave the normals out");
  c->add_flag("--ascii", o->ascii, "ASCII PLY instead of binary");
  c->add_flag("-f,--force", o->force, "Replace the output file if it exists");
  addShapeOptions(*c, o->truth);
  c->callback([o, &exitCode] { exitCode = runGuarded("gen", [&] { return run(*o); }); });
}

}  // namespace iso::cli
