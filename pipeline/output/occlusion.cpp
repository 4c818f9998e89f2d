// Ambient occlusion baked into corners (pipeline/output/occlusion.h).
#include "pipeline/output/occlusion.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <numbers>

#include "iso/flat_map.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/writer.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

Vec3 add(const Vec3& a, const Vec3& b, double s) {
  return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]};
}

}  // namespace

std::array<Vec3, 2> tangents(const Vec3& n) {
  // An orthonormal basis (t, b, n) (Duff et al. 2017).
  const double sign = std::copysign(1.0, n[2]);
  const double a = -1.0 / (sign + n[2]), c = n[0] * n[1] * a;
  return {Vec3{1.0 + sign * n[0] * n[0] * a, sign * c, -sign * n[0]},
          Vec3{c, sign + n[1] * n[1] * a, -n[1]}};
}

Vec3 cosineDirection(const Vec3& n, const std::array<Vec3, 2>& tb, int k, int rays,
                     const std::array<double, 2>& jitter) {
  // cos²θ uniform in [0, 1]: stratified in it, golden-ratio steps in azimuth.
  const double u = (k + jitter[0]) / rays;
  const double phi = 2.0 * std::numbers::pi * std::fmod(jitter[1] + k * 0.6180339887498949, 1.0);
  const double s = std::sqrt(u), z = std::sqrt(std::max(0.0, 1.0 - u));
  const double x = s * std::cos(phi), y = s * std::sin(phi);
  const Vec3 &t = tb[0], &b = tb[1];
  return {x * t[0] + y * b[0] + z * n[0], x * t[1] + y * b[1] + z * n[1],
          x * t[2] + y * b[2] + z * n[2]};
}

std::array<double, 2> rayJitter(uint64_t seed) {
  return {unitInterval(hashBits(seed)), unitInterval(hashBits(seed ^ 0x9e3779b97f4a7c15ull))};
}

RayStart leaveSurface(const SurfaceModel& surface, const Vec3& p, const Vec3& n) {
  // Start off the surface by a thousandth of the leaf there, and count hits from a twentieth of
  // it on: neighbouring leaves' patches agree at their faces only to within quantization, and a
  // ray near its start crossing such a face would meet that difference, not an occluder.
  const uint32_t leaf = surface.findLeaf(p);
  const uint8_t level = leaf == kNoNode ? surface.header().maxLevel : surface.leaves()[leaf].level;
  const double size = std::ldexp(1.0, -int(level));
  return {add(p, n, 1e-3 * size), 0.05 * size};
}

Vec3 surfaceNormal(const SurfaceModel& surface, uint32_t leaf, const Vec3& p) {
  // The interpolated stored normal (the points', within a fraction of a degree), unless it leans
  // more than 60° from the gradient's direction, which always points to the open side (f > 0):
  // stored normals interpolated across a leaf holding two facing sheets need not. The gradient of
  // a trilinear patch is degrees off (a sphere's light 10 % too low at cos θ = 0.37).
  const SurfaceEval e = surface.evaluate(leaf, p);
  const double length = std::hypot(e.gradient[0], e.gradient[1], e.gradient[2]);
  if (!(length > 0.0)) return {0.0, 0.0, 1.0};
  const Vec3 n{e.gradient[0] / length, e.gradient[1] / length, e.gradient[2] / length};
  const Vec3 stored{e.normal[0], e.normal[1], e.normal[2]};
  if (surface.hasNormals() && stored[0] * n[0] + stored[1] * n[1] + stored[2] * n[2] > 0.5)
    return stored;
  return n;
}

Receiver receiverOf(const SurfaceModel& surface, const Vec3& corner, Vec3 n, double distance) {
  // A corner lies on its leaf's boundary, often outside the filled leaves: the projection starts
  // from the corner's own estimate p − f·n, which lies near the zero set.
  Vec3 p = add(corner, n, -distance);
  std::optional<Vec3> q = surface.project(p);
  if (!q) q = surface.project(corner);
  if (!q) return {p, n, false};
  p = *q;
  const uint32_t leaf = surface.findLeaf(p);
  if (leaf != kNoNode) n = surfaceNormal(surface, leaf, p);
  return {p, n, true};
}

float ambientOcclusion(const SurfaceModel& surface, const Vec3& p, const Vec3& n, int rays,
                       double radius, uint64_t seed) {
  const std::array<Vec3, 2> tb = tangents(n);
  const RayStart start = leaveSurface(surface, p, n);
  const std::array<double, 2> jitter = rayJitter(seed);
  int open = 0;
  for (int k = 0; k < rays; ++k)
    if (!surface.intersect(start.origin, cosineDirection(n, tb, k, rays, jitter), start.tMin,
                           radius))
      ++open;
  return float(open) / float(rays);
}

uint64_t gridSeed(const GridPoint& g) {
  return hashBits(uint64_t(g.x) | uint64_t(g.y) << 21 | uint64_t(g.z) << 42);
}

FileHeader withOcclusion(FileHeader header) {
  for (const AttributeDesc& a : header.attributes)
    if (a.semantic == Semantic::Occlusion) return header;
  header.attributes.push_back({Semantic::Occlusion, Encoding::Unorm8, 1, 0.0f});
  return header;
}

OcclusionStats bakeOcclusion(const Reader& in, Writer& out, int rays, double radius) {
  const SurfaceModel surface = SurfaceModel::load(in);
  const FileHeader header = withOcclusion(in.header());
  OcclusionStats stats;
  std::atomic<uint64_t> unprojected{0};
  double sum = 0.0;
  // The occlusion at each corner: at its projection onto the zero set, seeded by its place.
  const auto bake = [&](std::span<const CornerKey> corners, CornerValues& values) {
    values.occlusion.resize(corners.size());
    tbb::parallel_for(size_t{0}, corners.size(), [&](size_t i) {
      const CornerKey& k = corners[i];
      const glm::dvec3 g = gridToFrame(k.point);
      const Receiver r =
          receiverOf(surface, {g.x, g.y, g.z},
                     {values.normal[i][0], values.normal[i][1], values.normal[i][2]},
                     double(values.distance[i]));
      if (!r.projected) unprojected.fetch_add(1, std::memory_order_relaxed);
      // Seeded by the grid point alone: a corner in several chunks gets one value.
      values.occlusion[i] =
          ambientOcclusion(surface, r.position, r.normal, rays, radius, gridSeed(k.point));
    });
    for (float o : values.occlusion) sum += o;
    stats.corners += corners.size();
  };
  for (const ChunkInfo& info : in.chunks()) {
    ChunkDesc desc{info.kind,      info.level,          info.key,
                   info.parent,    info.pointCount,     info.nodeCount,
                   info.leafCount, info.geometricError, Codec::Zstd};
    if (info.kind != kSurfaceKind) {  // copied as they are
      desc.codec = info.codec;
      out.addChunk(desc, in.payload(info.id).bytes());
      continue;
    }
    SurfaceChunk chunk = decodeSurfaceChunk(in, info.id);
    bake(chunk.layout.leafCorners, chunk.leafValues);
    bake(chunk.layout.lodCorners, chunk.lodValues);
    out.addChunk(desc, encodeSurfaceChunk(chunk.topology, chunk.layout, header.attributes,
                                          chunk.leafValues, chunk.lodValues));
  }
  stats.unprojected = unprojected.load();
  stats.rays = stats.corners * uint64_t(rays);
  stats.mean = stats.corners > 0 ? sum / double(stats.corners) : 1.0;
  return stats;
}

}  // namespace iso
