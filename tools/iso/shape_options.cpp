#include "tools/iso/shape_options.h"

#include <optional>
#include <stdexcept>
#include <vector>

#include "iso/error.h"
#include "base/text.h"
#include "pipeline/io/ply.h"

namespace iso::cli {

void addShapeOptions(CLI::App& c, ShapeOptions& o) {
  c.add_option("--mesh", o.mesh, "A triangle mesh (PLY, .ply.gz) instead of an analytic shape");
  c.add_option("--radius", o.params.radius, "Sphere radius; torus major radius")
      ->capture_default_str();
  c.add_option("--minor-radius", o.params.minorRadius, "Torus tube radius")->capture_default_str();
  c.add_option("--half-size", o.params.halfSize, "Cube half edge; plane and sheets half extent")
      ->capture_default_str();
  c.add_option("--gap", o.params.gap, "Distance between the two sheets")->capture_default_str();
  c.add_option("--center", o.center, "Shape centre x,y,z")->capture_default_str();
  c.add_option("--rotate", o.rotate,
                "Turn the shape about its centre: degrees about x, then y, then z (ax,ay,az)")
      ->capture_default_str();
  c.add_option("--offset", o.offset, "Added to every position, e.g. 500000,4900000,0 (UTM-like)")
      ->capture_default_str();
}

glm::dvec3 parseVector(const std::string& text, const char* option) {
  const std::optional<std::vector<double>> v = parseNumberList(text, 3);
  if (!v) throw UsageError(std::string(option) + " must be three numbers x,y,z, not '" + text + "'");
  return {(*v)[0], (*v)[1], (*v)[2]};
}

std::unique_ptr<Shape> makeTruth(const ShapeOptions& o) {
  const glm::dvec3 offset = parseVector(o.offset, "--offset");
  if (!o.mesh.empty()) {
    if (parseVector(o.rotate, "--rotate") != glm::dvec3(0.0))
      throw UsageError("--rotate turns analytic shapes, not --mesh");
    TriangleMesh mesh = readPlyMesh(o.mesh);
    for (glm::dvec3& v : mesh.vertices) v += offset;
    return makeMeshShape(std::move(mesh));
  }
  ShapeParams params = o.params;
  params.center = parseVector(o.center, "--center") + offset;
  params.rotation = parseVector(o.rotate, "--rotate");
  return makeShape(params);
}

}  // namespace iso::cli
