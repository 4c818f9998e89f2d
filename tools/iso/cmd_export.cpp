// `iso export FILE.iso [--mesh OUT.ply|OUT.glb [--level L] [--max-error E]] [--tiles OUT_DIR]
// [--vdb OUT.vdb] [--points OUT.ply]`: the surface of an .iso file for other tools, and the
// original points it keeps.
#include <fmt/core.h>

#include <unistd.h>

#include <cctype>
#include <chrono>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/export.h"
#include "pipeline/analysis/gltf.h"
#include "pipeline/analysis/tiles.h"
#include "pipeline/base/files.h"
#include "pipeline/io/ply.h"
#include "pipeline/output/keep_points.h"
#include "tools/iso/commands.h"
#include "tools/iso/interrupt.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

struct Options {
  std::string file, mesh, vdb, points, tiles, volumePoints;
  double band = 3.0;
  std::optional<int> level;        // --level: the level-of-detail cut the mesh is made at
  std::optional<double> maxError;  // --max-error: simplified within this (world units)
  std::optional<uint64_t> tileLeaves;  // --tile-leaves: at most this many leaves a finest tile
  bool force = false, json = false, noMeshopt = false;
};

// The mesh's format, from its extension: glTF binary for .glb, else PLY.
bool isGlb(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  for (char& c : extension) c = char(std::tolower(static_cast<unsigned char>(c)));
  return extension == ".glb";
}

int print(const nlohmann::json& summary, const Options& o);

double secondsSince(std::chrono::steady_clock::time_point started) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
}

// Every output, before the file is read: a directory that can take it, --force over an existing
// file, not the .iso file itself, and no file named by two options.
void checkOutputs(const Options& o) {
  const std::pair<std::string, const char*> outputs[] = {
      {o.mesh, "--mesh"},
      {o.vdb, "--vdb"},
      {o.points, "--points"},
      {o.volumePoints, "--volume-points"}};
  for (size_t i = 0; i < std::size(outputs); ++i) {
    const auto& [path, option] = outputs[i];
    if (path.empty()) continue;
    checkOutputPath(path, option, o.force);
    refuseOutputOverInput(path, o.file, option);
    for (size_t j = 0; j < i; ++j)
      if (!outputs[j].first.empty() && namesSameFile(outputs[j].first, path))
        throw UsageError(std::string(outputs[j].second) + " and " + option +
                         " name the same file: " + path);
  }
}

// Stage `final` in `outputs` and write it with `write`; errors name `final`, not the staged name.
void writeAs(OutputGroup& outputs, const std::string& final,
             const std::function<void(const std::filesystem::path& staged)>& write) {
  const std::filesystem::path staged = outputs.stage(final);
  try {
    write(staged);
  } catch (const FileError& error) {
    if (error.file() != staged.string()) throw;
    throw FileError(final, error.offset(), error.reason());
  }
}

void say(const std::string& doing) {
  setInterruptMessage("iso export: interrupted while " + doing +
                      "; nothing was written, temporary files removed");
}

// The kept points (kind kPointsKind, --points) or the volume points (--volume-points), with
// every value they keep as a double property of its name (NaN where a point has none).
void writePoints(const Reader& reader, uint8_t kind, const std::string& path,
                 OutputGroup& outputs, nlohmann::json& summary) {
  const bool volume = kind == kVolumePointsKind;
  const KeptPointsInfo kept = keptPointsInfo(reader, kind);
  if (kept.chunks == 0)
    throw FileError(reader.name(), std::nullopt,
                    volume ? "keeps no volume points (convert with --volume-points to keep them)"
                           : "keeps no points (convert with --keep-points to keep them)");
  say(volume ? "writing the volume points" : "writing the points");
  const auto started = std::chrono::steady_clock::now();
  const std::vector<std::string> names = keptValueNames(reader, kind);
  std::vector<std::vector<uint32_t>> valuesOf;
  for (const std::string& name : names) valuesOf.push_back(valuesChunks(reader, name));
  const std::vector<bool> subsample = subsampleChunks(reader);
  // Double positions: float would round them more coarsely than the file keeps them.
  writeAs(outputs, path, [&](const std::filesystem::path& staged) {
    PlyPointWriter ply(staged, kept.points, kept.normals, kept.colors,
                       {.doublePositions = true, .extraNames = names});
    for (const ChunkInfo& c : reader.chunks()) {
      if (c.kind != kind || subsample[c.id]) continue;
      PointCloud points = decodeKeptPoints(reader, c.id);
      points.extraNames = names;
      points.extras.assign(points.size() * names.size(), std::nan(""));
      for (size_t k = 0; k < names.size(); ++k) {
        if (valuesOf[k][c.id] == kNoParent) continue;
        const PointCloud values = decodeKeptPoints(reader, c.id, valuesOf[k][c.id]);
        for (size_t i = 0; i < points.size(); ++i)
          points.extras[i * names.size() + k] = values.extras[i];
      }
      ply.write(points);
    }
    ply.commit();
  });
  summary[volume ? "volume_points" : "points"] = {
      {"path", path},           {"points", kept.points},
      {"chunks", kept.chunks},  {"normals", kept.normals},
      {"colors", kept.colors},  {"values", names},
      {"seconds", secondsSince(started)}};
}

void writeMesh(const Reader& reader, const SurfaceModel& surface, bool doubles, const Options& o,
               OutputGroup& outputs, nlohmann::json& summary) {
  say("writing the mesh");
  const auto started = std::chrono::steady_clock::now();
  MeshStats stats;
  std::vector<uint32_t> vertexLeaves;
  TriangleMesh mesh = extractMesh(surface, &stats, &vertexLeaves);
  const uint64_t extracted = mesh.triangles.size();
  const bool glb = isGlb(o.mesh);
  MeshAttributes attributes;
  const std::optional<BakedAppearance> baked = bakedAppearance(reader);
  if (glb) attributes = meshAttributes(surface, mesh, vertexLeaves, baked ? &*baked : nullptr);
  vertexLeaves = {};
  double measured = 0.0;
  if (o.maxError) measured = simplifyMesh(mesh, attributes, *o.maxError);
  GlbStats glbStats;
  writeAs(outputs, o.mesh, [&](const std::filesystem::path& staged) {
    if (!glb) {
      writePlyMesh(staged, mesh, doubles);
      return;
    }
    optimizeMeshOrder(mesh, attributes);
    // 16-bit positions where their step is at most a hundredth of the finest leaf's edge.
    uint8_t finest = 0;
    for (const SurfaceModel::Leaf& leaf : surface.leaves()) finest = std::max(finest, leaf.level);
    GlbOptions options;
    options.compress = !o.noMeshopt;
    options.unlit = baked.has_value();
    options.maxPositionStep = 0.01 * std::ldexp(reader.header().frame.size, -int(finest));
    writeFileBytes(staged, encodeGlb(mesh, attributes, options, &glbStats));
  });
  summary["mesh"] = {{"path", o.mesh},
                     {"format", glb ? "glb" : "ply"},
                     {"vertices", mesh.vertices.size()},
                     {"triangles", mesh.triangles.size()},
                     {"leaves", stats.leaves},
                     {"tetrahedra", stats.tetrahedra},
                     {"split_faces", stats.splitFaces},
                     {"open_edges", openEdges(mesh)},
                     {"capped_holes", stats.cappedHoles},
                     {"double_positions", doubles && !glb},
                     {"seconds", secondsSince(started)}};
  if (o.level) summary["mesh"]["level"] = *o.level;
  if (o.maxError)
    summary["mesh"]["simplified"] = {
        {"max_error", *o.maxError}, {"triangles_before", extracted}, {"measured_error", measured}};
  if (glb)
    summary["mesh"]["glb"] = {{"bytes", glbStats.bytes},
                              {"quantized_positions", glbStats.quantized},
                              {"position_step", glbStats.positionStep},
                              {"meshopt", !o.noMeshopt},
                              {"normals", !attributes.normals.empty()},
                              {"colors", !attributes.colors.empty()}};
}

void writeLevelSet(const SurfaceModel& surface, const Options& o, OutputGroup& outputs,
                   nlohmann::json& summary) {
  say("writing the level set");
  const auto started = std::chrono::steady_clock::now();
  VdbStats stats;
  uint64_t bytes = 0;
  writeAs(outputs, o.vdb, [&](const std::filesystem::path& staged) {
    stats = writeVdb(surface, staged, o.band);
    bytes = std::filesystem::file_size(staged);
  });
  summary["vdb"] = {{"path", o.vdb},
                    {"active_voxels", stats.activeVoxels},
                    {"voxel_size", stats.voxelSize},
                    {"band_voxels", o.band},
                    {"bytes", bytes},
                    {"seconds", secondsSince(started)}};
}

void writeTileset(const Reader& reader, const Options& o, OutputDirectory& out,
                  nlohmann::json& summary) {
  say("writing the tileset");
  const auto started = std::chrono::steady_clock::now();
  const bool terminal = ::isatty(STDERR_FILENO) == 1;
  TilesOptions options;
  if (o.tileLeaves) options.finestLeaves = *o.tileLeaves;
  const TilesStats stats = writeTiles(reader, out.path(), options, [&](size_t done, size_t total) {
    if (terminal) fmt::print(stderr, "\rtiles: {} of {}", done, total);
  });
  if (terminal) fmt::print(stderr, "\n");
  nlohmann::json levels = nlohmann::json::array();
  for (const TilesLevel& l : stats.levels)
    levels.push_back({{"level", l.level},
                      {"tiles", l.tiles},
                      {"finest_tiles", l.finest},
                      {"triangles", l.triangles},
                      {"bytes", l.bytes},
                      {"finest_tiles_bytes", l.finestBytes},
                      {"largest_tile_triangles", l.largestTriangles},
                      {"largest_tile_bytes", l.largestBytes},
                      {"geometric_error", l.geometricError},
                      {"median_geometric_error", l.medianError},
                      {"to_children", l.toChildren}});
  summary["tiles"] = {{"path", o.tiles},
                      {"tiles", stats.tiles},
                      {"raised_errors", stats.raised},
                      {"largest_child_error_ratio", stats.largestChildRatio},
                      {"skirt_edges", stats.skirtEdges},
                      {"triangles", stats.triangles},
                      {"bytes", stats.bytes},
                      {"levels", levels},
                      {"seconds", secondsSince(started)}};
}

int run(const Options& o) {
  if (o.mesh.empty() && o.vdb.empty() && o.points.empty() && o.tiles.empty() &&
      o.volumePoints.empty())
    throw UsageError(
        "give --mesh OUT.ply, --tiles OUT_DIR, --vdb OUT.vdb, --points OUT.ply or "
        "--volume-points OUT.ply");
  if (!(o.band >= 1.0 && o.band <= 64.0)) throw UsageError("--band must be 1 to 64");
  if ((o.level || o.maxError || o.noMeshopt) && o.mesh.empty())
    throw UsageError("--level, --max-error and --no-meshopt shape the --mesh output: give --mesh");
  if (o.noMeshopt && !isGlb(o.mesh)) throw UsageError("--no-meshopt is for a .glb --mesh");
  if (o.tileLeaves && o.tiles.empty())
    throw UsageError("--tile-leaves shapes --tiles: give --tiles");
  if (o.tileLeaves && (*o.tileLeaves < 16 || *o.tileLeaves > (uint64_t{1} << 24)))
    throw UsageError("--tile-leaves must be 16 to 16,777,216");
  if (o.maxError && !(*o.maxError > 0.0 && std::isfinite(*o.maxError)))
    throw UsageError("--max-error must be a positive length (world units)");
  if (o.level && (*o.level < 0 || *o.level > int(kMaxLevel)))
    throw UsageError("--level must be 0 to " + std::to_string(kMaxLevel));
  if (!o.vdb.empty()) requireOpenVdb("--vdb");
  checkOutputs(o);
  say("reading " + o.file);
  const Reader reader = Reader::open(o.file);
  nlohmann::json summary = {{"file", o.file}};
  // Each output is written under a temporary name, and all are renamed into place once all are
  // complete: a failure (or Ctrl-C) leaves none of them, and every old file as it was.
  OutputGroup outputs;
  std::optional<OutputDirectory> tiles;
  if (!o.tiles.empty()) {
    tiles.emplace(o.tiles, "--tiles", o.force);
    writeTileset(reader, o, *tiles, summary);
  }
  if (!o.points.empty()) writePoints(reader, kPointsKind, o.points, outputs, summary);
  if (!o.volumePoints.empty())
    writePoints(reader, kVolumePointsKind, o.volumePoints, outputs, summary);
  if (!o.mesh.empty() || !o.vdb.empty()) {
    say("reading the surface of " + o.file);
    // The finest surface, and for --level the cut at that level (the leaves above it and the
    // nodes at it), each loaded only when an output reads it.
    const auto load = [&](uint8_t cutLevel) {
      return SurfaceModel::load(reader, {}, {}, cutLevel);
    };
    const std::optional<SurfaceModel> surface = !o.vdb.empty() || (!o.mesh.empty() && !o.level)
                                                    ? std::optional(load(kMaxLevel))
                                                    : std::nullopt;
    const std::optional<SurfaceModel> cut =
        o.level && !o.mesh.empty() ? std::optional(load(uint8_t(*o.level))) : std::nullopt;
    // Far from the origin (UTM coordinates) float positions lose the surface's detail.
    const Frame& frame = reader.header().frame;
    double reach = frame.size;
    for (double c : frame.origin) reach = std::max(reach, std::abs(c) + frame.size);
    if (!o.mesh.empty())
      writeMesh(reader, cut ? *cut : *surface, reach > 65536.0, o, outputs, summary);
    if (!o.vdb.empty()) writeLevelSet(*surface, o, outputs, summary);
  }
  {
    const InterruptsDeferred deferred;  // all renamed into place, or none
    outputs.commit();
    if (tiles) tiles->commit();
    setInterruptMessage("iso export: interrupted after writing its files");
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
    if (const uint64_t capped = m["capped_holes"].get<uint64_t>(); capped > 0)
      fmt::print("  closed {} small holes where the zero set leaves the filled leaves\n",
                 withSeparators(capped));
    if (m.contains("level"))
      fmt::print("  level-of-detail cut at level {}\n", m["level"].get<int>());
    if (m.contains("simplified")) {
      const auto& s = m["simplified"];
      fmt::print("  simplified from {} triangles within {:.6g} (measured: {:.6g})\n",
                 withSeparators(s["triangles_before"].get<uint64_t>()),
                 s["max_error"].get<double>(), s["measured_error"].get<double>());
    }
    if (m.contains("glb")) {
      const auto& g = m["glb"];
      fmt::print("  glTF binary, {}: {} positions{}{}{}\n", byteSize(g["bytes"].get<uint64_t>()),
                 g["quantized_positions"].get<bool>()
                     ? fmt::format("16-bit (step {:.3g})", g["position_step"].get<double>())
                     : std::string("float"),
                 g["normals"].get<bool>() ? ", normals" : "",
                 g["colors"].get<bool>() ? ", colors" : "",
                 g["meshopt"].get<bool>() ? ", meshopt-compressed" : ", uncompressed");
    }
  }
  if (summary.contains("tiles")) {
    const auto& t = summary["tiles"];
    fmt::print(
        "{}: 3D Tiles 1.1, {} tiles over {} levels, {} triangles, skirts on {} border edges, "
        "{} in {:.2f} s\n",
        o.tiles, withSeparators(t["tiles"].get<uint64_t>()), t["levels"].size(),
        withSeparators(t["triangles"].get<uint64_t>()),
        withSeparators(t["skirt_edges"].get<uint64_t>()), byteSize(t["bytes"].get<uint64_t>()),
        t["seconds"].get<double>());
    for (const auto& l : t["levels"])
      fmt::print(
          "  level {:>2}: {:>6} tiles ({} finest), {:>10} triangles (at most {} a tile), {:>10}, "
          "geometric error {:.4g} (median {:.4g})\n",
          l["level"].get<int>(), l["tiles"].get<uint64_t>(), l["finest_tiles"].get<uint64_t>(),
          withSeparators(l["triangles"].get<uint64_t>()),
          withSeparators(l["largest_tile_triangles"].get<uint64_t>()),
          byteSize(l["bytes"].get<uint64_t>()), l["geometric_error"].get<double>(),
          l["median_geometric_error"].get<double>());
  }
  for (const char* key : {"points", "volume_points"}) {
    if (!summary.contains(key)) continue;
    const auto& p = summary[key];
    std::string values;
    for (const auto& name : p["values"]) values += ", " + name.get<std::string>();
    fmt::print("{}: {} {} from {} chunks{}{}{} in {:.2f} s\n", p["path"].get<std::string>(),
               withSeparators(p["points"].get<uint64_t>()),
               std::string(key) == "points" ? "points" : "volume points",
               withSeparators(p["chunks"].get<uint64_t>()),
               p["normals"].get<bool>() ? ", with normals" : "",
               p["colors"].get<bool>() ? ", with colors" : "", values, p["seconds"].get<double>());
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
      "Write the surface of an .iso file for other tools: a triangle mesh (PLY or glTF), a 3D "
      "Tiles tileset, an OpenVDB level set, or the original points it keeps; all the outputs "
      "asked for, or none");
  c->add_option("file", o->file, ".iso file")->required()->check(CLI::ExistingFile);
  c->add_option("--mesh", o->mesh,
                "Triangle mesh of the zero set, crack-free across levels (each leaf cut into "
                "tetrahedra that match its neighbours' faces): glTF binary for a .glb name "
                "(16-bit positions, normals and colors, meshopt-compressed), else binary PLY");
  c->add_option("--tiles", o->tiles,
                "3D Tiles 1.1 tileset (a directory: tileset.json and a .glb a tile): a tile for "
                "each octree cell with surface from the frame's cube down (and coarser tiles of "
                "the frame above), its content the cell's surface cut some levels below it, "
                "simplified; a level of tiles for each halving of the error, each tile's "
                "geometric error measured against the finest tiles below it (`iso eval --tiles "
                "--depth D` checks them)");
  c->add_option("--tile-leaves", o->tileLeaves,
                "With --tiles: the most leaves with surface a finest tile holds (about 4 "
                "triangles a leaf; coarser tiles' contents are about as large); default 8192");
  c->add_option("--level", o->level,
                "Make the mesh from the level-of-detail cut at this octree level (the leaves "
                "above it and the nodes at it) instead of the finest leaves");
  c->add_option("--max-error", o->maxError,
                "Simplify the mesh (meshoptimizer's edge collapses) within this distance of the "
                "unsimplified one (world units, measured both ways); open borders stay");
  c->add_flag("--no-meshopt", o->noMeshopt,
              "Write the .glb mesh's buffers uncompressed, for tools that do not read "
              "EXT_meshopt_compression");
  c->add_option("--vdb", o->vdb,
                "OpenVDB narrow-band level set (float grid \"surface\"), voxels the finest "
                "leaves' size (not in builds without OpenVDB)");
  c->add_option("--points", o->points,
                "The original points (binary PLY with their normals, colors and kept values), "
                "when the file keeps them (iso convert --keep-points [--keep-scalar NAME])");
  c->add_option("--volume-points", o->volumePoints,
                "The volume points with their values (binary PLY), when the file keeps them (iso "
                "convert --volume-points)");
  c->add_option("--band", o->band, "Half width of the --vdb narrow band, in voxels")
      ->capture_default_str();
  c->add_flag("-f,--force", o->force, "Replace output files that exist");
  c->add_flag("--json", o->json, "Print the summary as JSON");
  c->callback([o, &exitCode] { exitCode = runGuarded("export", [&] { return run(*o); }); });
}

}  // namespace iso::cli
