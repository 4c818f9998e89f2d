// `iso export FILE.iso [--mesh OUT.ply] [--vdb OUT.vdb] [--points OUT.ply]`: the surface of an
// .iso file for other tools, and the original points it keeps.
#include <fmt/core.h>

#include <chrono>
#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/export.h"
#include "pipeline/io/ply.h"
#include "pipeline/output/keep_points.h"
#include "tools/iso/commands.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

struct Options {
  std::string file, mesh, vdb, points;
  double band = 3.0;
  bool force = false, json = false;
};

int print(const nlohmann::json& summary, const Options& o);

void refuseToReplace(const std::string& path, bool force) {
  if (std::filesystem::exists(path) && !force)
    throw FileError(path, std::nullopt, "exists already (use --force to replace it)");
}

int run(const Options& o) {
  if (o.mesh.empty() && o.vdb.empty() && o.points.empty())
    throw UsageError("give --mesh OUT.ply, --vdb OUT.vdb or --points OUT.ply");
  if (!(o.band >= 1.0 && o.band <= 64.0)) throw UsageError("--band must be 1 to 64");
  for (const std::string& out : {o.mesh, o.vdb, o.points})
    if (!out.empty()) refuseToReplace(out, o.force);
  const Reader reader = Reader::open(o.file);
  nlohmann::json summary = {{"file", o.file}};
  // Far from the origin (UTM coordinates) float positions lose the surface's detail.
  const Frame& frame = reader.header().frame;
  double reach = frame.size;
  for (double c : frame.origin) reach = std::max(reach, std::abs(c) + frame.size);
  const bool doubles = reach > 65536.0;
  if (!o.points.empty()) {
    const KeptPointsInfo kept = keptPointsInfo(reader);
    if (kept.chunks == 0)
      throw FileError(o.file, std::nullopt,
                      "keeps no points (convert with --keep-points to keep them)");
    const auto started = std::chrono::steady_clock::now();
    // Double positions: float would round them more coarsely than the file keeps them.
    PlyPointWriter ply(o.points, kept.points, kept.normals, kept.colors, {.doublePositions = true});
    forEachKeptPoints(reader, [&](const PointCloud& points) { ply.write(points); });
    ply.commit();
    summary["points"] = {
        {"path", o.points},
        {"points", kept.points},
        {"chunks", kept.chunks},
        {"normals", kept.normals},
        {"colors", kept.colors},
        {"seconds",
         std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()}};
  }
  if (o.mesh.empty() && o.vdb.empty()) return print(summary, o);
  const SurfaceModel surface = SurfaceModel::load(reader);
  if (!o.mesh.empty()) {
    const auto started = std::chrono::steady_clock::now();
    MeshStats stats;
    const TriangleMesh mesh = extractMesh(surface, &stats);
    writePlyMesh(o.mesh, mesh, doubles);
    summary["mesh"] = {
        {"path", o.mesh},
        {"vertices", mesh.vertices.size()},
        {"triangles", mesh.triangles.size()},
        {"leaves", stats.leaves},
        {"tetrahedra", stats.tetrahedra},
        {"split_faces", stats.splitFaces},
        {"open_edges", openEdges(mesh)},
        {"double_positions", doubles},
        {"seconds",
         std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()}};
  }
  if (!o.vdb.empty()) {
    const auto started = std::chrono::steady_clock::now();
    const VdbStats stats = writeVdb(surface, o.vdb, o.band);
    summary["vdb"] = {
        {"path", o.vdb},
        {"active_voxels", stats.activeVoxels},
        {"voxel_size", stats.voxelSize},
        {"band_voxels", o.band},
        {"bytes", std::filesystem::file_size(o.vdb)},
        {"seconds",
         std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count()}};
  }
  return print(summary, o);
}

int print(const nlohmann::json& summary, const Options& o) {
  if (o.json) {
    fmt::print("{}\n", summary.dump(2));
    return kExitOk;
  }
  if (summary.contains("mesh")) {
    const auto& m = summary["mesh"];
    const uint64_t open = m["open_edges"].get<uint64_t>();
    fmt::print("{}: {} triangles, {} vertices from {} leaves in {:.2f} s\n", o.mesh,
               withSeparators(m["triangles"].get<uint64_t>()),
               withSeparators(m["vertices"].get<uint64_t>()),
               withSeparators(m["leaves"].get<uint64_t>()), m["seconds"].get<double>());
    fmt::print("  open edges: {}{}\n", withSeparators(open),
               open > 0 ? " (where the surface is open or leaves the filled leaves)" : " (closed)");
  }
  if (summary.contains("points")) {
    const auto& p = summary["points"];
    fmt::print("{}: {} points from {} chunks{}{} in {:.2f} s\n", o.points,
               withSeparators(p["points"].get<uint64_t>()),
               withSeparators(p["chunks"].get<uint64_t>()),
               p["normals"].get<bool>() ? ", with normals" : "",
               p["colors"].get<bool>() ? ", with colors" : "", p["seconds"].get<double>());
  }
  if (summary.contains("vdb")) {
    const auto& v = summary["vdb"];
    fmt::print("{}: level set of {} active voxels of {:.6g} (band {} voxels), {} in {:.2f} s\n",
               o.vdb, withSeparators(v["active_voxels"].get<uint64_t>()),
               v["voxel_size"].get<double>(), o.band, byteSize(v["bytes"].get<uint64_t>()),
               v["seconds"].get<double>());
  }
  return kExitOk;
}

}  // namespace

void addExportCommand(CLI::App& app, int& exitCode) {
  auto o = std::make_shared<Options>();
  CLI::App* c = app.add_subcommand(
      "export",
      "Write the surface of an .iso file for other tools: a triangle mesh (PLY), an OpenVDB "
      "level set, or the original points it keeps");
  c->add_option("file", o->file, ".iso file")->required()->check(CLI::ExistingFile);
  c->add_option("--mesh", o->mesh,
                "Triangle mesh of the zero set (binary PLY), crack-free across levels: each leaf "
                "cut into tetrahedra that match its neighbours' faces (marching tetrahedra)");
  c->add_option("--vdb", o->vdb,
                "OpenVDB narrow-band level set (float grid \"surface\"), voxels the finest "
                "leaves' size");
  c->add_option("--points", o->points,
                "The original points (binary PLY with their normals and colors), when the file "
                "keeps them (iso convert --keep-points)");
  c->add_option("--band", o->band, "Half width of the --vdb narrow band, in voxels")
      ->capture_default_str();
  c->add_flag("-f,--force", o->force, "Replace output files that exist");
  c->add_flag("--json", o->json, "Print the summary as JSON");
  c->callback([o, &exitCode] { exitCode = runGuarded("export", [&] { return run(*o); }); });
}

}  // namespace iso::cli
