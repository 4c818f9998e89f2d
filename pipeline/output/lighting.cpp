// Light maps baked into lighting chunks (pipeline/output/lighting.h).
#include "pipeline/output/lighting.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>

#include "iso/error.h"
#include "iso/flat_map.h"
#include "iso/lighting.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/writer.h"
#include "pipeline/base/progress.h"
#include "pipeline/output/occlusion.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

using Rgb = std::array<double, 3>;

// Corner c (key, values) as a receiver of light (receiverOf).
Receiver cornerReceiver(const SurfaceModel& surface, const CornerKey& key,
                        const CornerValues& values, size_t c) {
  const glm::dvec3 g = gridToFrame(key.point);
  Vec3 normal{0.0, 0.0, 1.0};
  if (!values.normal.empty()) normal = {values.normal[c][0], values.normal[c][1], values.normal[c][2]};
  return receiverOf(surface, {g.x, g.y, g.z}, normal, double(values.distance[c]));
}

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// The light a sample point of a light (world units) brings to p (frame units, normal n):
// radiance × cos θ (over r² in world units), or nothing when it is behind p or the surface hides
// it.
void addSample(const SurfaceModel& surface, const RayStart& start, const Vec3& p, const Vec3& n,
               const BakeLight& light, const Vec3& world, double weight, Rgb& sum,
               uint64_t& rays) {
  const Frame& frame = surface.header().frame;
  const Vec3 at{(world[0] - frame.origin[0]) / frame.size, (world[1] - frame.origin[1]) / frame.size,
                (world[2] - frame.origin[2]) / frame.size};
  const Vec3 l{at[0] - p[0], at[1] - p[1], at[2] - p[2]};
  const double r = std::hypot(l[0], l[1], l[2]);
  if (!(r > 0.0)) return;
  const Vec3 d{l[0] / r, l[1] / r, l[2] / r};
  const double cosine = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
  if (!(cosine > 0.0)) return;
  ++rays;
  // The segment to the light, from the start's origin (a thousandth of a leaf off p).
  const Vec3 to{at[0] - start.origin[0], at[1] - start.origin[1], at[2] - start.origin[2]};
  const double length = std::hypot(to[0], to[1], to[2]);
  if (surface.intersect(start.origin, d, start.tMin, length)) return;
  double w = weight * cosine;
  if (light.inverseSquare) w /= r * r * frame.size * frame.size;
  for (size_t k = 0; k < 3; ++k) sum[k] += w * double(light.radiance[k]);
}

}  // namespace

std::array<double, 3> directIrradiance(const SurfaceModel& surface, const Vec3& p, const Vec3& n,
                                       const std::vector<BakeLight>& lights, uint64_t seed,
                                       uint64_t* shadowRays) {
  const RayStart start = leaveSurface(surface, p, n);
  Rgb sum{};
  uint64_t rays = 0;
  for (size_t i = 0; i < lights.size(); ++i) {
    const BakeLight& light = lights[i];
    if (!light.area) {
      addSample(surface, start, p, n, light, light.position, 1.0, sum, rays);
      continue;
    }
    // Stratified over a near-square grid of cells of the parallelogram, jittered per corner (as
    // the viewer samples it per pixel).
    const int samples = std::max(light.samples, 1);
    const int columns = int(std::ceil(std::sqrt(double(samples))));
    const int rows = (samples + columns - 1) / columns;
    for (int s = 0; s < samples; ++s) {
      const uint64_t bits = hashBits(seed ^ hashBits(uint64_t(i) << 32 | uint64_t(s)));
      const double a = (double(s % columns) + unitInterval(bits)) / columns - 0.5;
      const double b = (double(s / columns) + unitInterval(hashBits(bits))) / rows - 0.5;
      const Vec3 at{light.position[0] + a * light.u[0] + b * light.v[0],
                    light.position[1] + a * light.u[1] + b * light.v[1],
                    light.position[2] + a * light.u[2] + b * light.v[2]};
      addSample(surface, start, p, n, light, at, 1.0 / samples, sum, rays);
    }
  }
  if (shadowRays) *shadowRays += rays;
  return sum;
}

void validateLightBake(const LightBakeOptions& o) {
  const auto require = [](bool ok, const char* what) {
    if (!ok) throw UsageError(what);
  };
  require(!o.lights.empty(), "a light bake needs a scene with at least one light");
  require(o.bounces >= 0 && o.bounces <= 16, "--bounces must be 0 to 16");
  require(o.rays >= 1 && o.rays <= 4096, "--bake-rays must be 1 to 4096");
  require(std::isfinite(o.diffuse) && o.diffuse >= 0.0f && o.diffuse <= 1.0f,
          "the material's diffuse weight must be 0 to 1 for a light bake");
  for (float c : o.color)
    require(std::isfinite(c) && c >= 0.0f && c <= 1.0f,
            "the material's color must be 0 to 1 for a light bake");
  for (const BakeLight& l : o.lights) {
    require(l.samples >= 1 && l.samples <= 1024, "a light's samples must be 1 to 1024");
    for (float c : l.radiance)
      require(std::isfinite(c) && c >= 0.0f, "a light's color and intensity must be positive");
    for (const auto* v : {&l.position, &l.u, &l.v})
      for (double x : *v) require(std::isfinite(x), "a light's position and edges must be finite");
  }
}

nlohmann::json lightBakeJson(const LightBakeOptions& o) {
  nlohmann::json lights = nlohmann::json::array();
  for (const BakeLight& l : o.lights) {
    nlohmann::json j{{"type", l.area ? "area" : "point"},
                     {"position", l.position},
                     {"radiance", l.radiance},
                     {"falloff", l.inverseSquare ? "inverse_square" : "none"}};
    if (l.area) {
      j["u"] = l.u;
      j["v"] = l.v;
      j["samples"] = l.samples;
    }
    lights.push_back(std::move(j));
  }
  return {{"lights", lights},
          {"bounces", o.bounces},
          {"rays", o.rays},
          {"color", o.color},
          {"diffuse", o.diffuse}};
}

nlohmann::json LightBakeStats::json() const {
  const double corners = double(std::max<uint64_t>(receivers, 1));
  return {{"receivers", receivers},
          {"lod_corners", lodCorners},
          {"unprojected", unprojected},
          {"bounces", bounces},
          {"rays_per_corner", rays},
          {"shadow_rays", shadowRays},
          {"bounce_rays", bounceRays},
          {"own_corners", ownCorners},
          {"mean_irradiance", mean},
          {"direct_error",
           {{"samples", errorSamples},
            {"rms", errorRms},
            {"p95", errorP95},
            {"max", errorMax}}},
          // What depends on the machine (a file's metadata leaves it out).
          {"timing",
           {{"direct_seconds", directSeconds},
            {"bounce_seconds", bounceSeconds},
            {"seconds_per_million_corners_per_bounce",
             bounces > 0 ? bounceSeconds / bounces / (corners * 1e-6) : 0.0},
            {"bounce_rays_per_second",
             bounceSeconds > 0.0 ? double(bounceRays) / bounceSeconds : 0.0}}}};
}

FileHeader withLighting(FileHeader header) {
  header.versionMajor = kFormatMajor;
  header.versionMinor = kFormatMinor;
  return header;
}

namespace {

// A corner of leaf `leaf` as its own leaf's zero set sees it: Newton steps on the leaf's trilinear
// from the corner (frame units), or none when they do not converge.
std::optional<Receiver> leafReceiver(const SurfaceModel& surface, uint32_t leaf, Vec3 p) {
  const double edge = std::ldexp(1.0, -int(surface.leaves()[leaf].level));
  for (int step = 0; step < 16; ++step) {
    Vec3 g{};
    const double f = surface.distanceAt(leaf, p, &g);
    const double g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
    if (!(g2 > 0.0)) return std::nullopt;
    const double length = std::sqrt(g2);
    if (std::abs(f) < 1e-5 * edge * length)
      return Receiver{p, {g[0] / length, g[1] / length, g[2] / length}, true};
    for (size_t a = 0; a < 3; ++a) p[a] -= f * g[a] / g2;
  }
  return std::nullopt;
}

}  // namespace

LightBakeStats bakeLighting(const Reader& in, Writer& out, const LightBakeOptions& options) {
  validateLightBake(options);
  // The chunks to copy: all but the lighting chunks, which must come last (their ids are then
  // the only ones that change).
  uint32_t kept = 0;
  for (const ChunkInfo& c : in.chunks()) {
    if (c.kind == kLightingKind) continue;
    if (kept != c.id)
      throw FileError(in.name(), c.offset,
                      "chunk " + std::to_string(c.id) +
                          " comes after a lighting chunk: its lighting cannot be replaced "
                          "without renumbering the chunks");
    ++kept;
  }
  // Every surface chunk, decoded once: the model's and the output's.
  std::vector<std::shared_ptr<const SurfaceChunk>> decoded(in.chunks().size());
  for (const ChunkInfo& c : in.chunks())
    if (c.kind == kSurfaceKind)
      decoded[c.id] = std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(in, c.id));
  const SurfaceModel surface =
      SurfaceModel::load(in, std::nullopt, [&](uint32_t id) { return decoded[id]; });
  const std::span<const SurfaceModel::CornerSource> sources = surface.cornerSources();
  const std::span<const SurfaceModel::Leaf> leaves = surface.leaves();
  const size_t corners = sources.size();
  LightBakeStats stats;
  stats.bounces = options.bounces;
  stats.rays = options.rays;

  // The receivers: the finest surface's corners, each at its projection onto the zero set.
  std::vector<Receiver> receivers(corners);
  std::vector<uint64_t> seeds(corners);
  std::atomic<uint64_t> unprojected{0};
  tbb::parallel_for(size_t{0}, corners, [&](size_t i) {
    const SurfaceModel::CornerSource& s = sources[i];
    const SurfaceChunk& chunk = *decoded[s.chunk];
    const CornerValues& v = s.lod ? chunk.lodValues : chunk.leafValues;
    const CornerKey& key = (s.lod ? chunk.layout.lodCorners : chunk.layout.leafCorners)[s.corner];
    receivers[i] = cornerReceiver(surface, key, v, s.corner);
    if (!receivers[i].projected) unprojected.fetch_add(1, std::memory_order_relaxed);
    seeds[i] = gridSeed(key.point);
  });
  // A leaf's corner whose projection lies on another side of the surface than the leaf's own zero
  // set (a corner inside a thin wall, shared by the leaves of both its faces) is a receiver of its
  // own for that leaf: the light of one face never reaches the other through it.
  std::vector<std::array<uint32_t, 8>> slots(leaves.size());
  std::vector<std::vector<std::pair<uint8_t, Receiver>>> own(leaves.size());
  tbb::parallel_for(size_t{0}, leaves.size(), [&](size_t l) {
    const SurfaceModel::Leaf& leaf = leaves[l];
    const double edge = std::ldexp(1.0, -int(leaf.level));
    for (int c = 0; c < kCorners; ++c) {
      slots[l][size_t(c)] = leaf.corners[size_t(c)];
      const Receiver& shared = receivers[leaf.corners[size_t(c)]];
      if (!shared.projected) continue;
      const glm::dvec3 g = gridToFrame(cornerPoint(leaf.level, leaf.key, c));
      const std::optional<Receiver> mine = leafReceiver(surface, uint32_t(l), {g.x, g.y, g.z});
      if (!mine) continue;
      const Vec3& a = shared.normal;
      const Vec3& b = mine->normal;
      const double apart = std::hypot(shared.position[0] - mine->position[0],
                                      shared.position[1] - mine->position[1],
                                      shared.position[2] - mine->position[2]);
      if (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] < 0.0 || apart > 1.5 * edge)
        own[l].push_back({uint8_t(c), *mine});
    }
  });
  for (size_t l = 0; l < leaves.size(); ++l)
    for (const auto& [c, r] : own[l]) {
      slots[l][c] = uint32_t(receivers.size());
      receivers.push_back(r);
      seeds.push_back(hashBits(seeds[leaves[l].corners[c]] ^ uint64_t(l)));
    }
  own = {};
  const size_t n = receivers.size();
  stats.receivers = corners;
  stats.ownCorners = n - corners;
  // The value of v at p in leaf l, interpolated over its corners' receivers.
  const auto interpolate = [&](const std::vector<Rgb>& v, uint32_t l, const Vec3& p) {
    const std::array<double, 8> w = surface.cornerWeights(l, p);
    Rgb e{};
    for (size_t c = 0; c < 8; ++c)
      for (size_t a = 0; a < 3; ++a) e[a] += w[c] * v[slots[l][c]][a];
    return e;
  };

  // Direct light.
  auto clock = std::chrono::steady_clock::now();
  std::vector<Rgb> direct(n), total(n), previous, next(n);
  std::atomic<uint64_t> shadowRays{0};
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    uint64_t rays = 0;
    direct[i] = directIrradiance(surface, receivers[i].position, receivers[i].normal,
                                 options.lights, seeds[i], &rays);
    shadowRays.fetch_add(rays, std::memory_order_relaxed);
    progressAdvance(1);
  });
  total = direct;
  previous = direct;
  stats.shadowRays = shadowRays.load();
  stats.directSeconds = seconds(clock);

  // Bounces: the irradiance that bounce k brings to a corner is the mean over cosine-weighted
  // rays of reflectance × the irradiance bounce k − 1 left where each ray lands (the Monte-Carlo
  // estimate of ∫ ρ E / π cos dω); rays that leave the scene or land on a back face bring none.
  clock = std::chrono::steady_clock::now();
  const auto reflectance = [&](uint32_t leaf, const Vec3& p) {
    Rgb rho{options.color[0], options.color[1], options.color[2]};
    if (surface.hasColors()) {
      const std::array<float, 3> c = surface.evaluate(leaf, p).color;
      rho = {c[0], c[1], c[2]};
    }
    for (double& x : rho) x *= options.diffuse;
    return rho;
  };
  const int rays = std::max(options.rays, 1);
  for (int bounce = 1; bounce <= options.bounces; ++bounce) {
    tbb::parallel_for(size_t{0}, n, [&](size_t i) {
      const Receiver& r = receivers[i];
      const std::array<Vec3, 2> tb = tangents(r.normal);
      const RayStart start = leaveSurface(surface, r.position, r.normal);
      const std::array<double, 2> jitter = rayJitter(seeds[i] ^ hashBits(uint64_t(bounce)));
      Rgb sum{};
      for (int k = 0; k < rays; ++k) {
        const Vec3 d = cosineDirection(r.normal, tb, k, rays, jitter);
        const std::optional<RayHit> hit =
            surface.intersect(start.origin, d, start.tMin, std::numeric_limits<double>::max());
        if (!hit) continue;
        const Vec3 q{start.origin[0] + hit->t * d[0], start.origin[1] + hit->t * d[1],
                     start.origin[2] + hit->t * d[2]};
        Vec3 gradient{};
        surface.distanceAt(hit->leaf, q, &gradient);
        if (gradient[0] * d[0] + gradient[1] * d[1] + gradient[2] * d[2] >= 0.0) continue;
        const Rgb e = interpolate(previous, hit->leaf, q);
        const Rgb rho = reflectance(hit->leaf, q);
        for (size_t a = 0; a < 3; ++a) sum[a] += rho[a] * e[a];
      }
      for (size_t a = 0; a < 3; ++a) {
        next[i][a] = sum[a] / rays;
        total[i][a] += next[i][a];
      }
      progressAdvance(1);
    });
    std::swap(previous, next);
  }
  stats.bounceRays = uint64_t(n) * uint64_t(rays) * uint64_t(std::max(options.bounces, 0));
  stats.bounceSeconds = seconds(clock);
  for (size_t i = 0; i < corners; ++i)
    for (size_t a = 0; a < 3; ++a) stats.mean[a] += total[i][a] / double(std::max<size_t>(corners, 1));

  // What the corners give against the direct light computed where it is drawn: at points of the
  // zero set (at most 20,000), the interpolated direct irradiance against the exact one.
  {
    const std::vector<ZeroSetSample> samples = surface.sampleZeroSet(1);
    std::vector<BakeLight> reference = options.lights;
    for (BakeLight& l : reference) l.samples = std::min(4 * l.samples, 4096);
    const size_t every = std::max<size_t>(1, samples.size() / 20000);
    std::vector<double> errors((samples.size() + every - 1) / every), truths(errors.size());
    tbb::parallel_for(size_t{0}, errors.size(), [&](size_t k) {
      const ZeroSetSample& s = samples[k * every];
      const Vec3 normal = surfaceNormal(surface, s.leaf, s.position);
      // Four times the area lights' samples: the reference's own noise left out.
      const Rgb exact = directIrradiance(surface, s.position, normal, reference,
                                         hashBits(uint64_t(k) + 1));
      const Rgb drawn = interpolate(direct, s.leaf, s.position);
      truths[k] = (exact[0] + exact[1] + exact[2]) / 3.0;
      errors[k] = (std::abs(drawn[0] - exact[0]) + std::abs(drawn[1] - exact[1]) +
                   std::abs(drawn[2] - exact[2])) / 3.0;
    });
    double meanTruth = 0.0, sum2 = 0.0;
    for (size_t k = 0; k < errors.size(); ++k) {
      meanTruth += truths[k] / double(errors.size());
      sum2 += errors[k] * errors[k];
    }
    stats.errorSamples = errors.size();
    std::sort(errors.begin(), errors.end());
    if (!errors.empty() && meanTruth > 0.0) {
      stats.errorRms = std::sqrt(sum2 / double(errors.size())) / meanTruth;
      stats.errorP95 = errors[errors.size() * 95 / 100] / meanTruth;
      stats.errorMax = errors.back() / meanTruth;
    }
  }

  // The output: the input's chunks as they are, then a lighting chunk per surface chunk. Leaf
  // corners take their receiver's irradiance, a leaf's own corners theirs; LOD corners the finest
  // surface's at their projection onto it (interpolated there as a viewer interpolates it).
  std::vector<std::vector<uint32_t>> receiverIndex(in.chunks().size());
  for (size_t i = 0; i < corners; ++i) {
    const SurfaceModel::CornerSource& s = sources[i];
    if (s.lod) continue;
    std::vector<uint32_t>& map = receiverIndex[s.chunk];
    if (map.empty()) map.assign(decoded[s.chunk]->layout.leafCorners.size(), kNoNode);
    map[s.corner] = uint32_t(i);
  }
  const auto rgb = [](const Rgb& e) { return std::array<float, 3>{float(e[0]), float(e[1]), float(e[2])}; };
  std::atomic<uint64_t> lodUnprojected{0};
  const auto lightCorners = [&](std::span<const CornerKey> keys, const CornerValues& values,
                                const std::vector<uint32_t>* map) {
    std::vector<std::array<float, 3>> lit(keys.size());
    tbb::parallel_for(size_t{0}, keys.size(), [&](size_t c) {
      if (map && c < map->size() && (*map)[c] != kNoNode) {
        lit[c] = rgb(total[(*map)[c]]);
        return;
      }
      const Receiver r = cornerReceiver(surface, keys[c], values, c);
      if (!r.projected) lodUnprojected.fetch_add(1, std::memory_order_relaxed);
      const uint32_t leaf = surface.findLeaf(r.position);
      if (leaf != kNoNode) lit[c] = rgb(interpolate(total, leaf, r.position));
    });
    return lit;
  };
  for (const ChunkInfo& c : in.chunks())
    if (c.kind != kLightingKind) out.copyChunk(c, in.bytes().subspan(c.offset, c.storedSize));
  for (const ChunkInfo& c : in.chunks()) {
    if (c.kind != kSurfaceKind) continue;
    const SurfaceChunk& chunk = *decoded[c.id];
    ChunkLighting lighting;
    lighting.surfaceChunk = c.id;
    lighting.leaf = lightCorners(chunk.layout.leafCorners, chunk.leafValues, &receiverIndex[c.id]);
    lighting.lod = lightCorners(chunk.layout.lodCorners, chunk.lodValues, nullptr);
    for (uint32_t i = 0; i < chunk.layout.nodes.size(); ++i) {
      const SurfaceNode& node = chunk.layout.nodes[i];
      if (!node.isLeaf()) continue;
      const glm::dvec3 middle = gridToFrame(cornerPoint(node.level, node.key, 0)) +
                                glm::dvec3(0.5 * std::ldexp(1.0, -int(node.level)));
      const uint32_t leaf = surface.findLeaf({middle.x, middle.y, middle.z});
      if (leaf == kNoNode) continue;
      for (uint8_t k = 0; k < kCorners; ++k)
        if (slots[leaf][k] >= corners) lighting.overrides.push_back({i, k, rgb(total[slots[leaf][k]])});
    }
    stats.lodCorners += chunk.layout.lodCorners.size();
    ChunkDesc desc;
    desc.kind = kLightingKind;
    desc.level = c.level;
    desc.key = c.key;
    out.addChunk(desc, encodeLightingChunk(lighting));
  }
  stats.unprojected = unprojected.load() + lodUnprojected.load();
  return stats;
}

}  // namespace iso
