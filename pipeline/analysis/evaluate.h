// Accuracy of an .iso surface against a known answer (`iso eval`): an analytic shape or a mesh,
// measured both ways, or the input points themselves. All distances in world units.
//
//   iso → truth   area-weighted samples of the zero set (SurfaceModel::sampleZeroSet), each at
//                 its distance to the truth's closest point; the normal angle there
//   truth → iso   uniform samples of the truth projected onto the zero set; a sample that finds
//                 no zero set takes its distance to the nearest zero-set sample instead
//   holes         rays from outside aimed through the truth (closed: at points just inside it,
//                 which every ray must cross the surface to reach; open: at surface points, grazing
//                 rays left out): the fraction that hit the truth but not the zero set
// The combined "rms" is sqrt((rms_iso→truth² + rms_truth→iso²) / 2); "max" the larger max.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>

#include "iso/surface_model.h"
#include "pipeline/geom/shape.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct EvalOptions {
  uint64_t rays = 100000;          // for the hole rate
  uint64_t truthSamples = 200000;  // for truth → iso
  int linesPerEdge = 4;            // zero-set sampling density per leaf
  bool orientedNormals = true;  // false: normal angles ignore the sign (meshes of unknown winding)
  uint64_t seed = 1;
};

// pointSpacing: the input's point spacing (world units), the unit of the *_over_spacing values.
nlohmann::json evaluateAgainstShape(const SurfaceModel& surface, const Shape& truth,
                                    double pointSpacing, const EvalOptions& options = {});

// Distances of the points to the zero set (the conversion report's measure) with their spacing,
// and, when both the points and the file have colors, the color error: the file's color where
// each point projects onto the zero set against the point's, as the PSNR of 8-bit sRGB values
// ("color_psnr_db"; null when there is nothing to compare).
nlohmann::json evaluateAgainstPoints(const SurfaceModel& surface, const PointCloud& points);
// The same with the points' spacing given (computed once for many surfaces).
nlohmann::json evaluateAgainstPoints(const SurfaceModel& surface, const PointCloud& points,
                                     double pointSpacing);

// evaluateAgainstPoints for each level-of-detail cut of the file (SurfaceModel::load's cutLevel),
// from the coarsest level with nodes to the deepest leaves: what the viewer draws at that level.
// JSON array of {"level", "patches", and evaluateAgainstPoints' values}.
nlohmann::json evaluateLevels(const Reader& reader, const PointCloud& points);

// Two files against each other: area-weighted samples of each zero set projected onto the other
// ("a_to_b", "b_to_a": rms, max, mean in world units, samples, unprojected); "rms" combines them
// as evaluateAgainstShape does; with colors in both, "color_psnr_db": the 8-bit sRGB PSNR of a's
// color at its samples against b's where they project.
nlohmann::json evaluateAgainstFile(const SurfaceModel& a, const SurfaceModel& b,
                                   int linesPerEdge = 2);

// A triangle mesh against a truth, both ways by closest points: the one metric for surfaces that
// other tools make (an OpenVDB level set's or screened Poisson's mesh) and for an .iso file's
// exported mesh beside them. "mesh_to_truth": area-uniform samples of the mesh; "truth_to_mesh":
// samples of the truth; "rms" and "max" combined as evaluateAgainstShape does; *_over_spacing in
// pointSpacing; "beyond_half_spacing" and "beyond_two_spacings" the shares of samples farther than
// that (the mean of the two ways), "bulk_rms_over_spacing" the RMS of those within two spacings.
nlohmann::json evaluateMeshAgainstShape(const TriangleMesh& mesh, const Shape& truth,
                                        double pointSpacing, uint64_t samples = 100000,
                                        uint64_t seed = 1);

// The same against a scan's own points: "mesh_to_truth" is the distance of each mesh sample to
// the nearest point (a surface where the scan has no points is far from all of them; on a perfect
// surface it is still up to about half a spacing), "truth_to_mesh" that of each point (up to
// `samples` of them, evenly spread) to the mesh.
nlohmann::json evaluateMeshAgainstPoints(const TriangleMesh& mesh, const PointCloud& points,
                                         double pointSpacing, uint64_t samples = 100000,
                                         uint64_t seed = 1);

}  // namespace iso
