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

double unit(uint64_t bits) { return double(bits >> 11) * 0x1.0p-53; }

Vec3 add(const Vec3& a, const Vec3& b, double s) {
  return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]};
}

}  // namespace

float ambientOcclusion(const SurfaceModel& surface, const Vec3& p, const Vec3& n, int rays,
                       double radius, uint64_t seed) {
  // An orthonormal basis (t, b, n) (Duff et al. 2017).
  const double sign = std::copysign(1.0, n[2]);
  const double a = -1.0 / (sign + n[2]), c = n[0] * n[1] * a;
  const Vec3 t{1.0 + sign * n[0] * n[0] * a, sign * c, -sign * n[0]};
  const Vec3 b{c, sign + n[1] * n[1] * a, -n[1]};
  // Start off the surface by a thousandth of the leaf there, and count hits from a twentieth of
  // it on: neighbouring leaves' patches agree at their faces only to within quantization, and a
  // ray near its start crossing such a face would meet that difference, not an occluder.
  const uint32_t leaf = surface.findLeaf(p);
  const uint8_t level = leaf == kNoNode ? surface.header().maxLevel : surface.leaves()[leaf].level;
  const double size = std::ldexp(1.0, -int(level));
  const Vec3 origin = add(p, n, 1e-3 * size);
  const double jitterU = unit(hashBits(seed)),
               jitterPhi = unit(hashBits(seed ^ 0x9e3779b97f4a7c15ull));
  int open = 0;
  for (int k = 0; k < rays; ++k) {
    // Cosine-weighted: cos²θ uniform in [0, 1]; stratified in it, golden-ratio steps in azimuth.
    const double u = (k + jitterU) / rays;
    const double phi = 2.0 * std::numbers::pi * std::fmod(jitterPhi + k * 0.6180339887498949, 1.0);
    const double s = std::sqrt(u), z = std::sqrt(std::max(0.0, 1.0 - u));
    const double x = s * std::cos(phi), y = s * std::sin(phi);
    const Vec3 d{x * t[0] + y * b[0] + z * n[0], x * t[1] + y * b[1] + z * n[1],
                 x * t[2] + y * b[2] + z * n[2]};
    if (!surface.intersect(origin, d, 0.05 * size, radius)) ++open;
  }
  return float(open) / float(rays);
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
      const Vec3 corner{g.x, g.y, g.z};
      Vec3 n{values.normal[i][0], values.normal[i][1], values.normal[i][2]};
      // A corner lies on its leaf's boundary, often outside the filled leaves: the projection
      // starts from the corner's own estimate p − f·n, which lies near the zero set.
      Vec3 p = add(corner, n, -double(values.distance[i]));
      std::optional<Vec3> q = surface.project(p);
      if (!q) q = surface.project(corner);
      if (q) {
        p = *q;
        const uint32_t leaf = surface.findLeaf(p);
        // The gradient's direction, which always points to the open side (f > 0); stored
        // normals interpolated across a leaf holding two facing sheets need not.
        if (leaf != kNoNode) {
          const Vec3 g = surface.evaluate(leaf, p).gradient;
          const double length = std::hypot(g[0], g[1], g[2]);
          if (length > 0.0) n = {g[0] / length, g[1] / length, g[2] / length};
        }
      } else {
        unprojected.fetch_add(1, std::memory_order_relaxed);
      }
      // Seeded by the grid point alone: a corner in several chunks gets one value.
      const uint64_t seed =
          hashBits(uint64_t(k.point.x) | uint64_t(k.point.y) << 21 | uint64_t(k.point.z) << 42);
      values.occlusion[i] = ambientOcclusion(surface, p, n, rays, radius, seed);
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
