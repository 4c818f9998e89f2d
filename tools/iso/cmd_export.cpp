// `iso export FILE.iso --mesh OUT.ply`: the surface of an .iso file for other tools.
#include <fmt/core.h>

#include <chrono>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "export.h"
#include "io/ply.h"
#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "text.h"

namespace iso::cli {
namespace {

struct Options {
  std::string file, mesh;
  bool force = false, json = false;
};

void refuseToReplace(const std::string& path, bool force) {
  if (std::filesystem::exists(path) && !force)
    throw FileError(path, std::nullopt, "exists already (use --force to replace it)");
}

int run(const Options& o) {
  if (o.mesh.empty()) throw std::invalid_argument("give --mesh OUT.ply");
  refuseToReplace(o.mesh, o.force);
  const auto started = std::chrono::steady_clock::now();
  const Reader reader = Reader::open(o.file);
  const SurfaceModel surface = SurfaceModel::load(reader);
  MeshStats stats;
  const TriangleMesh mesh = extractMesh(surface, &stats);
  // Far from the origin (UTM coordinates) float positions lose the surface's detail.
  const Frame& frame = reader.header().frame;
  double reach = frame.size;
  for (double c : frame.origin) reach = std::max(reach, std::abs(c) + frame.size);
  const bool doubles = reach > 65536.0;
  writePlyMesh(o.mesh, mesh, doubles);
  const uint64_t open = openEdges(mesh);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  if (o.json) {
    const nlohmann::json j = {{"file", o.file},
                              {"mesh", o.mesh},
                              {"vertices", mesh.vertices.size()},
                              {"triangles", mesh.triangles.size()},
                              {"leaves", stats.leaves},
                              {"tetrahedra", stats.tetrahedra},
                              {"split_faces", stats.splitFaces},
                              {"open_edges", open},
                              {"double_positions", doubles},
                              {"seconds", seconds}};
    fmt::print("{}\n", j.dump(2));
    return kExitOk;
  }
  fmt::print("{}: {} triangles, {} vertices from {} leaves in {:.2f} s\n", o.mesh,
             withSeparators(mesh.triangles.size()), withSeparators(mesh.vertices.size()),
             withSeparators(stats.leaves), seconds);
  fmt::print("  open edges: {}{}\n", withSeparators(open),
             open > 0 ? " (where the surface is open or leaves the filled leaves)" : " (closed)");
  return kExitOk;
}

}  // namespace

void addExportCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<Options>();
  CLI::App* c = app.add_subcommand(
      "export", "Write the surface of an .iso file for other tools: a triangle mesh (PLY)");
  c->add_option("file", o->file, ".iso file")->required()->check(CLI::ExistingFile);
  c->add_option("--mesh", o->mesh,
                "Triangle mesh of the zero set (binary PLY), crack-free across levels: each leaf "
                "cut into tetrahedra that match its neighbours' faces (marching tetrahedra)");
  c->add_flag("-f,--force", o->force, "Replace output files that exist");
  c->add_flag("--json", o->json, "Print the summary as JSON");
  c->callback([o, &exitCode] {
    exitCode = runGuarded("export", [&] {
      try {
        return run(*o);
      } catch (const std::invalid_argument& error) {
        fmt::print(stderr, "iso export: {}\n", error.what());
        return kExitUsage;
      }
    });
  });
}

}  // namespace iso::cli
