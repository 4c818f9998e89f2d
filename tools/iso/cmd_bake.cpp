// `iso bake FILE.iso -o OUT.iso --scene S.json`: light maps added to a finished file (the scene's
// lights traced against its surface, with diffuse bounces), every other chunk kept byte for byte.
#include <fmt/core.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "pipeline/base/files.h"
#include "pipeline/base/progress.h"
#include "pipeline/output/lighting.h"
#include "tools/iso/commands.h"
#include "tools/iso/light_bake.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

struct Options {
  std::string file, output, scene, progress = "auto";
  int bounces = LightBakeOptions{}.bounces, rays = LightBakeOptions{}.rays;
  bool force = false, json = false;
};

int run(const Options& o) {
  LightBakeOptions bake = lightBakeFromScene(o.scene, o.bounces, o.rays);
  validateLightBake(bake);
  const ProgressMode mode =
      o.progress == "auto"
          ? (isatty(fileno(stderr)) && !o.json ? ProgressMode::Line : ProgressMode::None)
          : named(kProgressNames, o.progress, "--progress", "auto, ");
  checkOutputPath(o.output, "-o", o.force);
  refuseOutputOverInput(o.output, o.file, "-o");
  const Reader in = Reader::open(o.file);
  // A damaged file is refused whole: the bake would copy its chunks as they are.
  const VerifyResult verified = verifyFile(in);
  if (!verified.ok())
    throw FileError(o.file, verified.problems.front().offset,
                    "is damaged (" + std::to_string(verified.problems.size()) + " problem" +
                        (verified.problems.size() == 1 ? "" : "s") +
                        ", `iso verify` lists them): " + verified.problems.front().reason);
  nlohmann::json metadata = nlohmann::json::parse(in.metadata(), nullptr, false);
  if (!metadata.is_object()) metadata = nlohmann::json::object();
  const auto started = std::chrono::steady_clock::now();
  Writer out(o.output, withLighting(in.header()));
  LightBakeStats stats;
  {
    ProgressReporter progress(mode);
    progress.begin("light bake", 0);
    stats = bakeLighting(in, out, bake);
    progress.end();
  }
  nlohmann::json report = stats.json();
  metadata["lighting"] = lightBakeJson(bake);
  metadata["lighting"]["report"] = report;
  metadata["lighting"]["report"].erase("timing");
  out.setMetadata(metadata.dump());
  out.finish();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  if (o.json) {
    report["file"] = o.output;
    report["seconds"] = seconds;
    fmt::print("{}\n", report.dump(2));
  } else {
    fmt::print("{}: light baked into {} in {:.2f} s\n", o.file, o.output, seconds);
    printLightBake(report);
  }
  return kExitOk;
}

}  // namespace

void addBakeCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<Options>();
  CLI::App* c = app.add_subcommand(
      "bake",
      "Bake a scene's lights into an .iso file: the irradiance at every corner of every level of "
      "detail (shadows, soft under area lights, and diffuse bounces), in a new file whose other "
      "chunks are the input's bytes");
  c->add_option("file", o->file, ".iso file to light")->required()->check(CLI::ExistingFile);
  c->add_option("-o,--output", o->output, "The lit .iso file to write")->required();
  c->add_option("--scene", o->scene,
                "Scene file (specs/viewer.md): its lights (\"falloff\": \"inverse_square\" for "
                "lights that fall off) and its material's color and diffuse weight")
      ->required()
      ->check(CLI::ExistingFile);
  addLightBakeOptions(c, o->bounces, o->rays, nullptr);
  c->add_flag("-f,--force", o->force, "Replace the output file if it exists");
  c->add_flag("--json", o->json, "Print the report as JSON");
  c->add_option("--progress", o->progress, "Progress on stderr: auto, line, json or none")
      ->capture_default_str();
  c->callback([o, &exitCode] { exitCode = runGuarded("bake", [&] { return run(*o); }); });
}

}  // namespace iso::cli
