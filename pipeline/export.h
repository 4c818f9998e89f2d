// Exports of an .iso file's surface for other tools (specs/pipeline.md §17): a triangle mesh of
// the zero set, crack-free across levels.
#pragma once

#include <cstdint>

#include "io/point_cloud.h"
#include "iso/surface_model.h"

namespace iso {

struct MeshStats {
  uint64_t leaves = 0;      // filled leaves
  uint64_t tetrahedra = 0;  // the leaves are cut into
  uint64_t splitFaces = 0;  // leaf faces next to finer leaves
};

// The zero set as triangles (world coordinates, counter-clockwise seen from outside, where the
// signed distance is positive), extracted leaf by leaf:
// - each face of a leaf is triangulated: in quarters where a finer leaf lies across it, fanned
//   from its centre where one of its edges touches a finer leaf, else by the diagonal from its
//   lowest corner; both leaves sharing a face triangulate it alike;
// - the leaf is cut into the tetrahedra joining its centre to those triangles, and each
//   tetrahedron's zero set (the linear interpolation of its corners' values) is a triangle or two;
// - the value at a point on leaf boundaries is the coarsest leaf's patch there, so every leaf that
//   uses the point reads one number; vertices lie on tetrahedron edges and are shared by edge.
// So the mesh has no cracks, also where leaves of different levels meet (2:1 balanced, as the
// pipeline writes them). A value of exactly 0 counts as a tiny positive one: the mesh is that of a
// field without zeros, edge-manifold, and closed where the file's zero set stays inside its filled
// leaves.
TriangleMesh extractMesh(const SurfaceModel& surface, MeshStats* stats = nullptr);

// The edges used by one triangle only: where the surface is open (or leaves the filled leaves).
uint64_t openEdges(const TriangleMesh& mesh);

}  // namespace iso
