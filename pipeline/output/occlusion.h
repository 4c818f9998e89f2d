// Ambient occlusion traced on the CPU against the finished surface and baked into its corners
// (specs/pipeline.md §16).
#pragma once

#include <array>
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

// Shared by the bakes (occlusion, lighting).
// Two unit tangents completing the unit normal n to an orthonormal basis.
std::array<Vec3, 2> tangents(const Vec3& n);
// Direction k of `rays` cosine-weighted ones over the hemisphere of n (tangents tb): stratified
// (k + j0)/rays in cos²θ and by the golden ratio from j1 in azimuth.
Vec3 cosineDirection(const Vec3& n, const std::array<Vec3, 2>& tb, int k, int rays,
                     const std::array<double, 2>& jitter);
// 53 random bits of a hash as a number in [0, 1).
inline double unitInterval(uint64_t bits) { return double(bits >> 11) * 0x1.0p-53; }
// The jitters (j0, j1) in [0, 1) of a seed.
std::array<double, 2> rayJitter(uint64_t seed);
// A corner's seed: its grid point alone, so that a corner in several chunks gets one value.
uint64_t gridSeed(const GridPoint& g);

// Where rays leaving the surface at p along the side of n start, and the t from which their hits
// count (hits nearer are the seams of quantization between leaves, not occluders).
struct RayStart {
  Vec3 origin{};
  double tMin = 0.0;
};
RayStart leaveSurface(const SurfaceModel& surface, const Vec3& p, const Vec3& n);

// The normal that lights the surface at p in a leaf: the interpolated stored normal, or the
// gradient's direction (which points to the open side) where they are more than 60° apart or the
// file has none.
Vec3 surfaceNormal(const SurfaceModel& surface, uint32_t leaf, const Vec3& p);

// A corner (frame units; its stored normal n and signed distance) as a receiver of light: its
// projection onto the zero set and the interpolated stored normal there (or the gradient's
// direction, which points to the open side, where they disagree or the file has no normals), or,
// when the projection fails, corner − distance · n and n (projected false).
struct Receiver {
  Vec3 position{}, normal{};
  bool projected = true;
};
Receiver receiverOf(const SurfaceModel& surface, const Vec3& corner, Vec3 n, double distance);

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
