// iso-bench-mesh positions SCAN OUT.ply
// iso-bench-mesh measure MESH.ply --spacing S (--shape NAME | --mesh TRUTH.ply | --points TRUTH)
//     [--samples N]
// The shared metric of `tools/run bench accuracy` for surfaces that are meshes: iso's exported mesh,
// OpenVDB's level set mesh, and the screened Poisson meshes of tools/bench/open3d_poisson.py.
// `positions` writes a scan's positions alone as binary PLY (for tools that read PLY but not LAS);
// `measure` prints evaluateMeshAgainstShape's or evaluateMeshAgainstPoints' JSON
// (pipeline/analysis/evaluate.h) with the spacing given (the iso conversion report's, so that every
// method is measured in the same unit).
#include <fmt/core.h>

#include <string>

#include "iso/error.h"
#include "pipeline/analysis/evaluate.h"
#include "pipeline/geom/shape.h"
#include "pipeline/io/ply.h"
#include "pipeline/io/readers.h"

namespace {

using namespace iso;

int positions(const std::string& scan, const std::string& out) {
  PointCloud cloud = readPointFile(scan);
  PointCloud bare;
  bare.positions = std::move(cloud.positions);
  writePly(out, bare);
  fmt::print("{{\"points\": {}}}\n", bare.size());
  return 0;
}

int measure(int argc, char** argv) {
  const std::string mesh = argv[2];
  std::string shapeName, truthMesh, truthPoints;
  double spacing = 0.0;
  uint64_t samples = 100000;
  for (int i = 3; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) throw UsageError("missing value after " + a);
    if (a == "--shape")
      shapeName = argv[++i];
    else if (a == "--mesh")
      truthMesh = argv[++i];
    else if (a == "--points")
      truthPoints = argv[++i];
    else if (a == "--spacing")
      spacing = std::stod(argv[++i]);
    else if (a == "--samples")
      samples = std::stoull(argv[++i]);
    else
      throw UsageError("unknown argument " + a);
  }
  if (!(spacing > 0.0)) throw UsageError("--spacing must be a positive number");
  const TriangleMesh surface = readPlyMesh(mesh);
  nlohmann::json result;
  if (!truthPoints.empty()) {
    result = evaluateMeshAgainstPoints(surface, readPointFile(truthPoints), spacing, samples);
  } else if (!truthMesh.empty()) {
    result = evaluateMeshAgainstShape(surface, *makeMeshShape(readPlyMesh(truthMesh)), spacing,
                                      samples);
  } else if (!shapeName.empty()) {
    ShapeParams params;
    params.name = shapeName;
    result = evaluateMeshAgainstShape(surface, *makeShape(params), spacing, samples);
  } else {
    throw UsageError("name the truth: --shape, --mesh or --points");
  }
  fmt::print("{}\n", result.dump(2));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string command = argc > 1 ? argv[1] : "";
  try {
    if (command == "positions" && argc == 4) return positions(argv[2], argv[3]);
    if (command == "measure" && argc >= 3) return measure(argc, argv);
    fmt::print(stderr,
               "usage: iso-bench-mesh positions SCAN OUT.ply\n"
               "       iso-bench-mesh measure MESH.ply --spacing S (--shape NAME | --mesh "
               "TRUTH.ply | --points TRUTH) [--samples N]\n");
    return 2;
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-bench-mesh: {}\n", error.what());
    return 1;
  }
}
