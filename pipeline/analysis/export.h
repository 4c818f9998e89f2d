// Exports of an .iso file's surface for other tools (specs/pipeline.md §17): a triangle mesh of
// the zero set, crack-free across levels.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <glm/vec3.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "iso/surface_model.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

class Reader;

struct MeshStats {
  uint64_t leaves = 0;      // filled leaves
  uint64_t tetrahedra = 0;  // the leaves are cut into
  uint64_t splitFaces = 0;  // leaf faces next to finer leaves
  uint64_t cappedHoles = 0;  // small holes closed where the zero set leaves the filled leaves
};

// The zero set as triangles (world coordinates, counter-clockwise seen from outside, where the
// signed distance is positive), extracted leaf by leaf:
// - each face of a leaf is triangulated: in quarters where a finer leaf lies across it, fanned
//   from its centre where one of its edges touches a finer leaf, else by the diagonal from its
//   lowest corner; both leaves sharing a face triangulate it alike;
// - a leaf with no finer leaf around is cut into the six tetrahedra around its diagonal from the
//   lowest corner; any other into the tetrahedra joining its centre to those triangles; each
//   tetrahedron's zero set (the linear interpolation of its corners' values) is a triangle or two;
// - the value at a point on leaf boundaries is the coarsest leaf's patch there, so every leaf that
//   uses the point reads one number; vertices lie on tetrahedron edges, at the zero of the patch
//   along the edge (the coarsest leaf's on boundaries), and are shared by edge.
// So the mesh has no cracks, also where leaves of different levels meet (2:1 balanced, as the
// pipeline writes them). A value of exactly 0 counts as a tiny positive one: the mesh is that of a
// field without zeros, edge-manifold, and closed where the file's zero set stays inside its filled
// leaves. Throws std::runtime_error for leaves of level kMaxLevel (the pipeline makes none).
// vertexLeaves, when given, receives the leaf whose tetrahedron made each vertex. With `within`
// (frame units), only the leaves whose cells lie inside it give triangles; the others are still
// sampled where they are coarser, so that meshes of neighbouring regions of one model (a region
// loaded with the leaves around it) agree on their shared faces. Leaves inside any of `without`
// give no triangles either.
TriangleMesh extractMesh(const SurfaceModel& surface, MeshStats* stats = nullptr,
                         std::vector<uint32_t>* vertexLeaves = nullptr,
                         const SurfaceModel::Region* within = nullptr,
                         std::span<const SurfaceModel::Region> without = {});

// A mesh's vertex attributes from the surface it was extracted from: at each vertex, its leaf's
// interpolated stored normal and linear color. Each is empty when the file has none.
struct MeshAttributes {
  std::vector<glm::vec3> normals, colors;
};

// What a file with baked lighting (iso bake) looks like lit: the bake's material (its metadata's
// "lighting": the color of surfaces without their own, the diffuse weight), or none for a file
// without lighting chunks.
struct BakedAppearance {
  std::array<float, 3> color{0.75f, 0.75f, 0.72f};
  float diffuse = 0.9f;
};
std::optional<BakedAppearance> bakedAppearance(const Reader& reader);

// With `baked` (and a surface with irradiance), the colors are the lit ones: diffuse × color ×
// irradiance (linear, clamped to 1 by the encodings), what the viewer's baked lighting draws
// without its ambient and specular terms.
MeshAttributes meshAttributes(const SurfaceModel& surface, const TriangleMesh& mesh,
                              std::span<const uint32_t> vertexLeaves,
                              const BakedAppearance* baked = nullptr);

// The mesh (and its attributes) simplified by edge collapses (meshoptimizer) within maxError
// (world units): the largest distance between the two meshes, sampled both ways (every vertex of
// the mesh the result dropped, to the result; a grid of 25 points besides the corners on each of
// the result's triangles, to the mesh), is measured; where a few samples are beyond maxError, the
// triangles around them are kept as they were and the rest collapsed again, where many are, the
// collapses are redone with half the target, until none is beyond (the mesh stays as it was when
// six tries do not get there). Vertices on open borders stay; unused vertices are removed. Returns
// the measured distance (world units). Deterministic.
double simplifyMesh(TriangleMesh& mesh, MeshAttributes& attributes, double maxError);

// meshoptimizer's collapses within its own estimate, `target` (world units: how far vertices move
// from the planes around them), unmeasured: a needle's tip may go. For meshes whose distance to
// the surface is measured as a whole afterwards. Open borders stay; unused vertices are removed.
void collapseMesh(TriangleMesh& mesh, MeshAttributes& attributes, double target);

// Triangles reordered for the vertex cache and vertices renumbered in the order they are first
// used (meshoptimizer), as compression and drawing like them; unused vertices removed.
void optimizeMeshOrder(TriangleMesh& mesh, MeshAttributes& attributes);

// The surface's leaves, coarsest first (stable): where leaves of several levels meet, the exports
// take the first one's value.
std::vector<uint32_t> leavesCoarseFirst(const SurfaceModel& surface);

// The edges used by one triangle only: where the surface is open (or leaves the filled leaves).
uint64_t openEdges(const TriangleMesh& mesh);

// `mesh`'s vertices and triangles added to `to`'s.
void appendMesh(TriangleMesh& to, const TriangleMesh& mesh);

struct VdbStats {
  uint64_t activeVoxels = 0;
  double voxelSize = 0.0;  // world units: the finest leaf's edge
  int level = 0;           // the finest leaves' level
};

// Throw iso::UsageError naming `option` in builds without OpenVDB (ISO_WITH_OPENVDB=OFF:
// export_vdb_none.cpp), where writeVdb and sampleVdb throw it too; nothing in builds with it.
void requireOpenVdb(const std::string& option);

// The surface as an OpenVDB narrow-band level set (pipeline/analysis/export_vdb.cpp): a float grid
// named "surface" of class level set, voxel size the finest leaf's edge, voxel (i, j, k) at the
// frame's origin + (i, j, k)·size (the lattice points of the finest leaves). Every lattice point of
// a filled leaf whose signed distance (world units; the coarsest leaf's value where leaves meet) is
// within `bandVoxels` voxels of 0 is active; the rest of space takes ±bandVoxels·size by a signed
// flood fill (negative inside). Written atomically. Throws iso::FileError when it cannot write, or
// when the voxels are smaller than OpenVDB's transforms allow (about 1.44e-5 units).
VdbStats writeVdb(const SurfaceModel& surface, const std::filesystem::path& path,
                  double bandVoxels = 3.0);

// The first float grid of a .vdb file, trilinearly interpolated at world positions (OpenVDB's box
// sampler): for round trips and for measuring level sets made by other tools. Throws
// iso::FileError for files OpenVDB cannot read or without a float grid.
std::vector<double> sampleVdb(const std::filesystem::path& path, std::span<const glm::dvec3> world);

}  // namespace iso
