// Light maps (pipeline/output/lighting.h) against answers known exactly: the irradiance of a point
// light on a plane, the shadow of a sphere (umbra, and an area light's penumbra by brute force), a
// closed furnace's bounces, a thin wall, levels of detail, and what the bake keeps of its input.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <glm/geometric.hpp>
#include <random>

#include "iso/lighting.h"
#include "iso/reader.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "pipeline/base/options.h"
#include "pipeline/geom/generate.h"
#include "pipeline/geom/shape.h"
#include "pipeline/output/lighting.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

BakeLight pointLight(const glm::dvec3& at, float intensity, bool inverseSquare) {
  BakeLight light;
  light.position = {at.x, at.y, at.z};
  light.radiance = {intensity, intensity, intensity};
  light.inverseSquare = inverseSquare;
  return light;
}

// A light bake of `points` into path (and the conversion's report). A light map is as fine as the
// leaves: a flat plane's leaves are capped at `leafEdge` spacings (the octree's other tests
// let them grow to 128).
nlohmann::json bake(const PointCloud& points, const std::filesystem::path& path,
                    const LightBakeOptions& lighting, double leafEdge = 128.0) {
  BuildOptions options;
  options.maxTestedEdge = leafEdge;
  options.lighting = lighting;
  options.lighting.enabled = true;
  return convertToIso(points, path, options);
}

// Points of the file's zero set (world units) with the irradiance the file gives them and the
// unit normal there.
struct LitSample {
  glm::dvec3 world, normal;
  std::array<float, 3> irradiance;
};

// With `largestLeaf`: the edge of the model's largest leaf (world units).
std::vector<LitSample> litSamples(const std::filesystem::path& path, uint8_t cutLevel = kMaxLevel,
                                  double* largestLeaf = nullptr) {
  const Reader reader = Reader::open(path);
  const SurfaceModel surface = SurfaceModel::load(reader, std::nullopt, {}, cutLevel);
  EXPECT_TRUE(surface.hasIrradiance());
  const Frame& f = reader.header().frame;
  if (largestLeaf) {
    uint8_t coarsest = kMaxLevel;
    for (const SurfaceModel::Leaf& leaf : surface.leaves()) coarsest = std::min(coarsest, leaf.level);
    *largestLeaf = f.size * std::ldexp(1.0, -coarsest);
  }
  std::vector<LitSample> out;
  for (const ZeroSetSample& s : surface.sampleZeroSet(2)) {
    const SurfaceEval e = surface.evaluate(s.leaf, s.position);
    const glm::dvec3 g(e.gradient[0], e.gradient[1], e.gradient[2]);
    out.push_back({glm::dvec3(f.origin[0], f.origin[1], f.origin[2]) +
                       f.size * glm::dvec3(s.position[0], s.position[1], s.position[2]),
                   glm::normalize(g), e.irradiance});
  }
  return out;
}

TEST(Lighting, rgb9e5KeepsEveryChannelWithin2ToTheMinus9OfTheLargest) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> exponent(-12.0, 15.0), share(0.0, 1.0);
  double worstLargest = 0.0, worstOther = 0.0;
  for (int i = 0; i < 100000; ++i) {
    const double scale = std::exp2(exponent(rng));
    const std::array<float, 3> rgb{float(scale * share(rng)), float(scale * share(rng)),
                                   float(scale)};
    const std::array<float, 3> back = decodeRgb9e5(encodeRgb9e5(rgb));
    worstLargest = std::max(worstLargest, std::abs(double(back[2]) - rgb[2]) / rgb[2]);
    for (int c = 0; c < 2; ++c)
      worstOther = std::max(worstOther, std::abs(double(back[c]) - rgb[c]) / rgb[2]);
  }
  std::printf("RGB9E5 over 100,000 colors: largest channel within %.3g of itself, the others "
              "within %.3g of the largest\n",
              worstLargest, worstOther);
  EXPECT_LE(worstLargest, std::exp2(-9.0));
  EXPECT_LE(worstOther, std::exp2(-9.0));
  EXPECT_EQ(decodeRgb9e5(encodeRgb9e5({0.0f, -1.0f, std::nanf("")})),
            (std::array<float, 3>{0.0f, 0.0f, 0.0f}));
  EXPECT_EQ(decodeRgb9e5(encodeRgb9e5({1e9f, 1.0f, 0.0f}))[0], kMaxRgb9e5);
  EXPECT_EQ(decodeRgb9e5(encodeRgb9e5({1.0f, 0.5f, 0.25f})),
            (std::array<float, 3>{1.0f, 0.5f, 0.25f}));
}

TEST(Lighting, aPointLightOnAPlaneGivesCosOverRSquared) {
  test::TempDir dir;
  const PointCloud plane = test::scanOf("plane", 40000);  // |x|, |y| <= 1 at z = 0, facing +z
  const glm::dvec3 light(0.3, -0.2, 1.5);
  for (const bool inverseSquare : {true, false}) {
    SCOPED_TRACE(inverseSquare ? "inverse square" : "no falloff");
    LightBakeOptions options;
    options.lights = {pointLight(light, 2.0f, inverseSquare)};
    options.bounces = 0;
    const nlohmann::json report = bake(plane, dir / "plane.iso", options, 4.0);
    EXPECT_GT(report["lighting"]["receivers"].get<uint64_t>(), 1000u);
    double worst = 0.0;
    size_t checked = 0;
    for (const LitSample& s : litSamples(dir / "plane.iso")) {
      if (std::abs(s.world.x) > 0.8 || std::abs(s.world.y) > 0.8) continue;
      const glm::dvec3 l = light - s.world;
      const double r = glm::length(l);
      const double want = 2.0 * (l.z / r) / (inverseSquare ? r * r : 1.0);
      worst = std::max(worst, std::abs(double(s.irradiance[1]) - want) / want);
      ++checked;
    }
    std::printf("plane under a point light (%s): %zu points, largest error %.4f of the answer\n",
                inverseSquare ? "inverse square" : "no falloff", checked, worst);
    EXPECT_GT(checked, 1000u);
    EXPECT_LT(worst, 0.02);
  }
}

// A ball of radius 0.3 at height 0.6 over the plane, lit from above.
PointCloud ballOverPlane() {
  PointCloud points = test::scanOf("plane", 30000);
  ShapeParams ball;
  ball.radius = 0.3;
  ball.center = {0.0, 0.0, 0.6};
  const PointCloud sphere = test::scanOf(ball, 12000);
  for (size_t i = 0; i < sphere.size(); ++i) appendPoint(points, sphere, i);
  return points;
}

// The part of the segment from p to q that a ball (center c, radius r) does not block: 1 or 0.
bool clear(const glm::dvec3& p, const glm::dvec3& q, const glm::dvec3& c, double r) {
  const glm::dvec3 d = q - p;
  const double t = std::clamp(glm::dot(c - p, d) / glm::dot(d, d), 0.0, 1.0);
  return glm::length(p + t * d - c) > r;
}

TEST(Lighting, aBallCastsTheAnalyticShadowAndPenumbra) {
  test::TempDir dir;
  const PointCloud points = ballOverPlane();
  const glm::dvec3 c(0.0, 0.0, 0.6), light(0.0, 0.0, 2.0);
  const double r = 0.3, spacing = 2.0 / std::sqrt(30000.0);
  // A point light: the umbra is where the segment to the light meets the ball; points a few
  // spacings from its edge are lit or dark as the answer says.
  {
    LightBakeOptions options;
    options.lights = {pointLight(light, 1.0f, false)};
    options.bounces = 0;
    bake(points, dir / "point.iso", options, 4.0);
    size_t dark = 0, lit = 0, wrong = 0;
    for (const LitSample& s : litSamples(dir / "point.iso")) {
      if (std::abs(s.world.z) > 0.05 || std::abs(s.world.x) > 0.8 || std::abs(s.world.y) > 0.8)
        continue;  // the plane, away from its rim
      // The shadow's edge on the plane: the cone from the light tangent to the ball.
      const double rho = std::hypot(s.world.x, s.world.y);
      const double edge = 2.0 * std::tan(std::asin(r / (2.0 - 0.6)));
      if (std::abs(rho - edge) < 3.0 * spacing) continue;
      const double want = clear(s.world, light, c, r) ? (light - s.world).z / glm::length(light - s.world) : 0.0;
      (want > 0.0 ? lit : dark) += 1;
      if (std::abs(s.irradiance[0] - want) > 0.02) ++wrong;
    }
    std::printf("ball's shadow (point light): %zu points in the umbra, %zu lit, %zu wrong\n", dark,
                lit, wrong);
    EXPECT_GT(dark, 100u);
    EXPECT_GT(lit, 1000u);
    EXPECT_EQ(wrong, 0u);
  }
  // An area light (a square of edge 0.8): the share of it seen past the ball, by brute force over
  // a 48² grid of its points.
  {
    LightBakeOptions options;
    BakeLight area = pointLight(light, 1.0f, false);
    area.area = true;
    area.u = {0.8, 0.0, 0.0};
    area.v = {0.0, 0.8, 0.0};
    area.samples = 256;
    options.lights = {area};
    options.bounces = 0;
    bake(points, dir / "area.iso", options, 4.0);
    double worst = 0.0;
    size_t penumbra = 0, checked = 0;
    for (const LitSample& s : litSamples(dir / "area.iso")) {
      if (std::abs(s.world.z) > 0.05 || std::hypot(s.world.x, s.world.y) > 0.7) continue;
      if ((++checked) % 8 != 0) continue;  // an eighth of them: the brute force is slow
      double want = 0.0;
      constexpr int kGrid = 48;
      for (int i = 0; i < kGrid; ++i)
        for (int j = 0; j < kGrid; ++j) {
          const glm::dvec3 q = light + glm::dvec3(0.8 * ((i + 0.5) / kGrid - 0.5),
                                                  0.8 * ((j + 0.5) / kGrid - 0.5), 0.0);
          if (clear(s.world, q, c, r)) want += (q - s.world).z / glm::length(q - s.world);
        }
      want /= kGrid * kGrid;
      if (want > 0.05 && want < 0.85) ++penumbra;
      worst = std::max(worst, std::abs(double(s.irradiance[0]) - want));
    }
    std::printf("ball's shadow (area light, 256 samples): %zu points in the penumbra, largest "
                "error %.4f (1 = unshadowed)\n",
                penumbra, worst);
    EXPECT_GT(penumbra, 100u);
    EXPECT_LT(worst, 0.05);
  }
}

TEST(Lighting, bouncesInAClosedFurnaceConvergeToTheGeometricSeries) {
  // The inside of a ball of radius 1 (normals inwards), albedo a, a point light at its center
  // falling off as 1/r²: every point receives E = 1 directly, and after N bounces
  // E (1 − a^(N+1)) / (1 − a).
  test::TempDir dir;
  PointCloud points = test::scanOf("sphere", 20000);
  for (glm::vec3& n : points.normals) n = -n;
  const float a = 0.5f;
  for (const int bounces : {1, 3}) {
    LightBakeOptions options;
    options.lights = {pointLight({0.0, 0.0, 0.0}, 1.0f, true)};
    options.bounces = bounces;
    options.rays = 64;
    options.color = {a, a, a};
    options.diffuse = 1.0f;
    bake(points, dir / "furnace.iso", options);
    const double want = (1.0 - std::pow(a, bounces + 1)) / (1.0 - a);
    double sum = 0.0, sum2 = 0.0, worst = 0.0;
    const std::vector<LitSample> samples = litSamples(dir / "furnace.iso");
    for (const LitSample& s : samples) {
      // The direct light at the sample's own radius (the surface is not exactly at 1).
      const double scale = 1.0 / glm::dot(s.world, s.world);
      const double e = s.irradiance[0] / (scale * 1.0);
      sum += e;
      sum2 += e * e;
      worst = std::max(worst, std::abs(e - want));
    }
    const double n = double(samples.size()), mean = sum / n;
    const double spread = std::sqrt(std::max(0.0, sum2 / n - mean * mean));
    std::printf("furnace, albedo %.2f, %d bounces: mean %.5f (answer %.5f), spread %.5f, largest "
                "error %.5f over %zu points\n",
                a, bounces, mean, want, spread, worst, samples.size());
    EXPECT_NEAR(mean, want, 0.01 * want);
    EXPECT_LT(worst, 0.04 * want);
  }
}

TEST(Lighting, aThinWallLetsNoLightThrough) {
  // A slab of two sheets 2 spacings apart (|x|, |y| <= 1), lit from above: its underside gets
  // nothing, its top the light's cosine.
  ShapeParams params;
  params.name = "sheets";
  const double spacing = 2.0 / std::sqrt(60000.0);  // 60,000 points a sheet
  params.gap = 2.0 * spacing;
  const std::unique_ptr<Shape> slab = makeShape(params);
  GenerateOptions generate;
  generate.count = 120000;
  const PointCloud points = generateScan(*slab, generate);
  test::TempDir dir;
  LightBakeOptions options;
  options.lights = {pointLight({0.2, 0.1, 1.5}, 1.0f, false)};
  options.bounces = 2;
  options.rays = 32;
  const nlohmann::json report = bake(points, dir / "wall.iso", options);
  // The corners inside the wall light each face's leaves as that face.
  EXPECT_GT(report["lighting"]["own_corners"].get<uint64_t>(), 1000u);
  size_t under = 0, top = 0;
  double brightestUnder = 0.0, darkestTop = 1.0;
  for (const LitSample& s : litSamples(dir / "wall.iso")) {
    if (std::abs(s.world.x) > 0.8 || std::abs(s.world.y) > 0.8) continue;
    if (s.normal.z < -0.9) {
      ++under;
      brightestUnder = std::max(brightestUnder, double(s.irradiance[0]));
    } else if (s.normal.z > 0.9) {
      ++top;
      darkestTop = std::min(darkestTop, double(s.irradiance[0]));
    }
  }
  std::printf("thin wall (2 spacings): %zu points under it, the brightest %.3g; %zu on top, the "
              "darkest %.3f\n",
              under, brightestUnder, top, darkestTop);
  EXPECT_GT(under, 1000u);
  EXPECT_GT(top, 1000u);
  EXPECT_EQ(brightestUnder, 0.0);
  EXPECT_GT(darkestTop, 0.7);
}

TEST(Lighting, aCoarserCutsIrradianceIsTheFinestWithinItsInterpolationError) {
  // A plane (flat at every level) under a point light: a cut's irradiance at its surface is the
  // linear interpolation of the answer across its cells, within h²/8 of the largest second
  // derivative along each of the plane's two axes.
  test::TempDir dir;
  const glm::dvec3 light(0.3, -0.2, 0.8);
  LightBakeOptions options;
  options.lights = {pointLight(light, 1.0f, true)};
  options.bounces = 0;
  bake(test::scanOf("plane", 40000), dir / "plane.iso", options, 4.0);
  const Reader reader = Reader::open(dir / "plane.iso");
  const auto answer = [&](double x, double y) {
    const glm::dvec3 l = light - glm::dvec3(x, y, 0.0);
    return l.z / std::pow(glm::dot(l, l), 1.5);
  };
  double curvature = 0.0;  // the largest |∂²E/∂x²| or |∂²E/∂y²| over the plane, by differences
  const double h = 1e-3;
  for (double x = -1.0; x <= 1.0; x += 0.01)
    for (double y = -1.0; y <= 1.0; y += 0.01) {
      const double e = answer(x, y);
      curvature = std::max({curvature, std::abs(answer(x + h, y) - 2 * e + answer(x - h, y)) / (h * h),
                            std::abs(answer(x, y + h) - 2 * e + answer(x, y - h)) / (h * h)});
    }
  const uint8_t finest = reader.header().maxLevel;
  for (uint8_t level = uint8_t(finest - 3); level <= finest; ++level) {
    double cell = 0.0;
    const std::vector<LitSample> samples = litSamples(dir / "plane.iso", level, &cell);
    // Both axes' interpolation errors, and RGB9E5's rounding (2^-10 of the largest value).
    const double bound = 2.0 * cell * cell / 8.0 * curvature + 1e-3 * answer(0.3, -0.2);
    double worst = 0.0;
    for (const LitSample& s : samples) {
      if (std::abs(s.world.x) > 0.8 || std::abs(s.world.y) > 0.8) continue;
      worst = std::max(worst, std::abs(double(s.irradiance[0]) - answer(s.world.x, s.world.y)));
    }
    std::printf("plane, cut at level %d (largest leaf %.4g): largest error %.4g, bound %.4g\n",
                int(level), cell, worst, bound);
    EXPECT_LE(worst, bound) << "level " << int(level);
  }
}

TEST(Lighting, theBakeKeepsEveryOtherChunkByteForByteAndReplacesItsOwn) {
  test::TempDir dir;
  PointCloud points = test::scanOf("torus", 20000);
  points.colors.assign(points.size(), glm::vec3(0.3f, 0.5f, 0.7f));
  BuildOptions plain;
  plain.keepPoints = true;
  convertToIso(points, dir / "plain.iso", plain);
  LightBakeOptions options;
  options.lights = {pointLight({0.0, 0.0, 3.0}, 1.0f, false)};
  options.rays = 8;
  const auto bakeFile = [&](const std::filesystem::path& from, const std::filesystem::path& to) {
    const Reader in = Reader::open(from);
    Writer out(to, withLighting(in.header()));
    const LightBakeStats stats = bakeLighting(in, out, options);
    out.setMetadata(std::string(in.metadata()));
    out.finish();
    return stats;
  };
  bakeFile(dir / "plain.iso", dir / "lit.iso");
  const Reader in = Reader::open(dir / "plain.iso"), lit = Reader::open(dir / "lit.iso");
  EXPECT_TRUE(verifyFile(lit).ok());
  size_t surfaces = 0;
  for (const ChunkInfo& c : in.chunks()) {
    const ChunkInfo& d = lit.chunk(c.id);
    EXPECT_EQ(c.kind, d.kind);
    EXPECT_EQ(c.codec, d.codec);
    EXPECT_EQ(c.parent, d.parent);
    EXPECT_TRUE(std::ranges::equal(in.bytes().subspan(c.offset, c.storedSize),
                                   lit.bytes().subspan(d.offset, d.storedSize)))
        << "chunk " << c.id;
    surfaces += c.kind == kSurfaceKind ? 1 : 0;
  }
  ASSERT_EQ(lit.chunks().size(), in.chunks().size() + surfaces);
  const std::vector<uint32_t> of = lightingChunks(lit);
  for (const ChunkInfo& c : in.chunks())
    if (c.kind == kSurfaceKind) {
      ASSERT_NE(of[c.id], kNoParent);
      SurfaceChunk chunk = decodeSurfaceChunk(lit, c.id);
      attachLighting(lit, of[c.id], c.id, chunk);
      EXPECT_EQ(chunk.leafValues.irradiance.size(), chunk.layout.leafCorners.size());
    }
  // Baked again (other lights): the same number of chunks, the new lighting in place of the old,
  // and the bytes the same as a bake of the plain file.
  options.lights[0].radiance = {0.5f, 0.5f, 0.5f};
  bakeFile(dir / "lit.iso", dir / "again.iso");
  bakeFile(dir / "plain.iso", dir / "direct.iso");
  const Reader again = Reader::open(dir / "again.iso"), direct = Reader::open(dir / "direct.iso");
  ASSERT_EQ(again.chunks().size(), lit.chunks().size());
  for (uint32_t id = 0; id < again.chunks().size(); ++id)
    EXPECT_TRUE(std::ranges::equal(
        again.bytes().subspan(again.chunk(id).offset, again.chunk(id).storedSize),
        direct.bytes().subspan(direct.chunk(id).offset, direct.chunk(id).storedSize)))
        << "chunk " << id;
}

}  // namespace
}  // namespace iso
