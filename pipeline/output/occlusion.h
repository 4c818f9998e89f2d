// Ambient occlusion traced on the CPU against the finished surface and baked into its corners
// (specs/pipeline.md §16).
#pragma once

#include <cstdint>

#include "iso/format.h"
#include "iso/surface_model.h"

namespace iso {

class Reader;
class Writer;

// The unoccluded fraction of `rays` cosine-weighted directions over the hemisphere of the unit
// normal n at p (frame units): those that meet no surface within `radius`. The directions are
// stratified (k + j_k)/rays in cos²θ and by the golden ratio in azimuth, with jitters j from
// `seed`: the same seed gives the same answer.
float ambientOcclusion(const SurfaceModel& surface, const Vec3& p, const Vec3& n, int rays,
                       double radius, uint64_t seed);

struct OcclusionStats {
  uint64_t corners = 0;      // leaf and level-of-detail corners, counted once per chunk
  uint64_t unprojected = 0;  // corners whose projection onto the zero set failed (p − f·n used)
  uint64_t rays = 0;
  double mean = 0.0;  // mean occlusion value of the corners
};

// Copy the chunks of `in` to `out` (whose header is withOcclusion(in's)), every surface chunk
// with an occlusion value at each corner: the occlusion at the corner's projection onto the zero
// set, with the surface's normal there. `radius` in frame units. Deterministic (seeded by corner).
OcclusionStats bakeOcclusion(const Reader& in, Writer& out, int rays, double radius);

// The header with an occlusion attribute (unorm8) added, or kept when it has one.
FileHeader withOcclusion(FileHeader header);

}  // namespace iso
