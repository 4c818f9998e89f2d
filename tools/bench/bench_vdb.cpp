// iso-bench-vdb SCAN FILE.iso OUT.vdb (--shape NAME | --mesh TRUTH.ply | --points TRUTH)
//     [--radius-spacings R] [--voxel-scale F]
// The OpenVDB baseline of `tools/run bench accuracy`, on the points an .iso file was converted
// from, at its resolution (voxels the size of its finest leaves, times F: default 1). OpenVDB's
// ParticlesToLevelSet rasterizes a sphere around every point, of R spacings (default 2) but at
// least 2 voxels so that neighbours overlap; the union of spheres around surface points is a shell
// about the surface, 2 radii thick, so it is eroded (LevelSetFilter::offset) by the radius less one
// voxel, which leaves a shell a couple of voxels thick whose two sheets lie about a voxel from the
// surface, and smoothed by one mean-curvature step. Prints JSON: seconds, peak memory, .vdb bytes,
// and the error of its zero set's mesh (volumeToMesh) against the truth; and, with the same metric
// (evaluateMeshAgainstShape or evaluateMeshAgainstPoints), the error of the .iso file's exported
// mesh.
#include <fmt/core.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetFilter.h>
#include <openvdb/tools/ParticlesToLevelSet.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <chrono>
#include <cstring>
#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/evaluate.h"
#include "pipeline/analysis/export.h"
#include "pipeline/base/process.h"
#include "pipeline/convert/convert.h"
#include "pipeline/geom/shape.h"
#include "pipeline/io/ply.h"
#include "pipeline/io/readers.h"

namespace {

using namespace iso;

struct Particles {
  const PointCloud& cloud;
  double radius;
  using PosType = openvdb::Vec3R;
  size_t size() const { return cloud.size(); }
  void getPos(size_t n, openvdb::Vec3R& p) const {
    p = {cloud.positions[n].x, cloud.positions[n].y, cloud.positions[n].z};
  }
  void getPosRad(size_t n, openvdb::Vec3R& p, openvdb::Real& r) const {
    getPos(n, p);
    r = radius;
  }
};

TriangleMesh meshOf(const openvdb::FloatGrid& grid) {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(grid, points, triangles, quads, 0.0);
  TriangleMesh mesh;
  for (const auto& p : points) mesh.vertices.push_back({p.x(), p.y(), p.z()});
  for (const auto& t : triangles) mesh.triangles.push_back({t[0], t[1], t[2]});
  for (const auto& q : quads) {
    mesh.triangles.push_back({q[0], q[1], q[2]});
    mesh.triangles.push_back({q[0], q[2], q[3]});
  }
  return mesh;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5) {
    fmt::print(stderr,
               "usage: iso-bench-vdb SCAN FILE.iso OUT.vdb (--shape NAME | --mesh TRUTH.ply | "
               "--points TRUTH) [--radius-spacings R] [--voxel-scale F]\n");
    return 2;
  }
  try {
    const std::filesystem::path scan = argv[1], isoFile = argv[2], out = argv[3];
    std::string shapeName, truthMesh, truthPoints;
    double radiusSpacings = 2.0, voxelScale = 1.0;
    for (int i = 4; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "--shape" && i + 1 < argc)
        shapeName = argv[++i];
      else if (a == "--mesh" && i + 1 < argc)
        truthMesh = argv[++i];
      else if (a == "--points" && i + 1 < argc)
        truthPoints = argv[++i];
      else if (a == "--radius-spacings" && i + 1 < argc)
        radiusSpacings = std::stod(argv[++i]);
      else if (a == "--voxel-scale" && i + 1 < argc)
        voxelScale = std::stod(argv[++i]);
      else
        throw UsageError("unknown argument " + a);
    }
    openvdb::initialize();
    const PointCloud cloud = readPointFile(scan);
    const Reader reader = Reader::open(isoFile);
    const SurfaceModel surface = SurfaceModel::load(reader);
    int level = 0;
    for (const auto& leaf : surface.leaves()) level = std::max(level, int(leaf.level));
    const Frame& frame = reader.header().frame;
    const double voxel = voxelScale * std::ldexp(frame.size, -level);
    const double spacing = nlohmann::json::parse(reader.metadata())["report"]["spacing"];
    const double radius = std::max(radiusSpacings * spacing, 2.0 * voxel);
    // The baseline, timed: rasterize, erode by the radius, smooth.
    const auto started = std::chrono::steady_clock::now();
    openvdb::FloatGrid::Ptr grid = openvdb::createLevelSet<openvdb::FloatGrid>(voxel, 3.0);
    {
      openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*grid);
      raster.setRmin(0.0);  // keep spheres below 1.5 voxels too
      raster.rasterizeSpheres(Particles{cloud, radius});
      raster.finalize(true);
    }
    openvdb::tools::LevelSetFilter<openvdb::FloatGrid> filter(*grid);
    filter.offset(float(radius - voxel));
    filter.meanCurvature();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    openvdb::io::File file(out.string());
    file.write({grid});
    file.close();
    const uint64_t peak = peakRssBytes();
    nlohmann::json result = {
        {"voxel", voxel},
        {"radius", radius},
        {"seconds", seconds},
        {"peak_rss_bytes", peak},
        {"bytes", std::filesystem::file_size(out)},
        {"bytes_per_point", double(std::filesystem::file_size(out)) / double(cloud.size())},
        {"active_voxels", grid->activeVoxelCount()}};
    const TriangleMesh vdbMesh = meshOf(*grid);
    const TriangleMesh isoMesh = extractMesh(surface);
    if (!truthPoints.empty()) {
      const PointCloud truth = readPointFile(truthPoints);
      result["vdb_error"] = evaluateMeshAgainstPoints(vdbMesh, truth, spacing);
      result["iso_mesh_error"] = evaluateMeshAgainstPoints(isoMesh, truth, spacing);
    } else {
      std::unique_ptr<Shape> truth;
      if (!truthMesh.empty()) {
        truth = makeMeshShape(readPlyMesh(truthMesh));
      } else {
        ShapeParams params;
        params.name = shapeName;
        truth = makeShape(params);
      }
      result["vdb_error"] = evaluateMeshAgainstShape(vdbMesh, *truth, spacing);
      result["iso_mesh_error"] = evaluateMeshAgainstShape(isoMesh, *truth, spacing);
    }
    fmt::print("{}\n", result.dump(2));
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-bench-vdb: {}\n", error.what());
    return 1;
  }
  return 0;
}
