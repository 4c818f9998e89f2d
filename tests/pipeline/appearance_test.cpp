// Appearance baked into corners: triplanar textures (sampled at points or at corners) and ambient
// occlusion traced against the surface, against answers known exactly.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "iso/error.h"
#include "iso/quantize.h"
#include "pipeline/base/options.h"
#include "pipeline/output/occlusion.h"
#include "pipeline/output/texture.h"
#include "pipeline/points/points.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso {
namespace {

glm::vec3 linear(uint8_t r, uint8_t g, uint8_t b) {
  return {srgb8ToLinear(r), srgb8ToLinear(g), srgb8ToLinear(b)};
}

void expectColor(const glm::vec3& got, const glm::vec3& want, float tolerance = 1e-5f) {
  EXPECT_NEAR(got.r, want.r, tolerance);
  EXPECT_NEAR(got.g, want.g, tolerance);
  EXPECT_NEAR(got.b, want.b, tolerance);
}

// A 2 × 2 image: red, green on the top row; blue, white below.
LinearImage quad(const test::TempDir& dir) {
  test::writePpm(dir / "quad.ppm", 2, 2, {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255});
  return readLinearImage(dir / "quad.ppm");
}

TEST(Texture, imagesAreReadAsLinearColor) {
  test::TempDir dir;
  test::writePpm(dir / "one.ppm", 1, 1, {200, 100, 50});
  const LinearImage image = readLinearImage(dir / "one.ppm");
  ASSERT_EQ(image.width, 1u);
  expectColor(image.texels[0], linear(200, 100, 50));
  // Not an image, and no file: errors that name the file.
  test::writeFile(dir / "text.png", std::vector<std::byte>(40, std::byte{'x'}));
  for (const char* name : {"text.png", "missing.png"}) {
    try {
      readLinearImage(dir / name);
      ADD_FAILURE() << name << " was read";
    } catch (const FileError& error) {
      EXPECT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
    }
    EXPECT_THROW(checkImageReadable(dir / name), FileError);
  }
}

TEST(Texture, bilinearBetweenTexelCentresAndRepeating) {
  test::TempDir dir;
  const TriplanarTexture texture(quad(dir), 1.0, 4.0);
  const glm::vec3 red(1, 0, 0), green(0, 1, 0), blue(0, 0, 1), white(1, 1, 1);
  // Texel centres: u = 0.25 or 0.75, v up (v = 0.75 is the top row).
  expectColor(texture.sample(0.25, 0.75), red);
  expectColor(texture.sample(0.75, 0.75), green);
  expectColor(texture.sample(0.25, 0.25), blue);
  expectColor(texture.sample(0.75, 0.25), white);
  expectColor(texture.sample(0.5, 0.5), (red + green + blue + white) / 4.0f);
  expectColor(texture.sample(0.5, 0.75), (red + green) / 2.0f);
  // The image repeats: across u = 0 red meets green, and whole repeats change nothing.
  expectColor(texture.sample(0.0, 0.75), (red + green) / 2.0f);
  expectColor(texture.sample(-2.75, 3.25), texture.sample(0.25, 0.25));
}

TEST(Texture, triplanarWeightsAreAbsoluteNormalComponentsToThePowerP) {
  test::TempDir dir;
  const double scale = 2.0;
  const glm::dvec3 p(0.3, 1.1, -0.7);
  const auto plane = [&](const TriplanarTexture& t, int axis) {  // the sample along one axis
    const glm::dvec3 q = p / scale;
    return axis == 0 ? t.sample(q.y, q.z) : axis == 1 ? t.sample(q.x, q.z) : t.sample(q.x, q.y);
  };
  const TriplanarTexture sharp(quad(dir), scale, 4.0);
  // An axis normal sees its own plane alone, whichever its sign.
  expectColor(sharp.color(p, {1, 0, 0}), plane(sharp, 0));
  expectColor(sharp.color(p, {0, -1, 0}), plane(sharp, 1));
  expectColor(sharp.color(p, {0, 0, -3}), plane(sharp, 2));
  // Equal components: equal weights whatever P, and signs do not matter.
  expectColor(sharp.color(p, {1, -1, 0}), (plane(sharp, 0) + plane(sharp, 1)) / 2.0f);
  // (0.6, 0.8, 0) with P = 4: weights 0.1296 and 0.4096 (normalized).
  const float wx = 0.1296f / 0.5392f, wy = 0.4096f / 0.5392f;
  expectColor(sharp.color(p, {-0.6, 0.8, 0}), wx * plane(sharp, 0) + wy * plane(sharp, 1));
  // P = 0: the three planes alike.
  const TriplanarTexture flat(quad(dir), scale, 0.0);
  expectColor(flat.color(p, {0.1, 0.2, 0.9}),
              (plane(flat, 0) + plane(flat, 1) + plane(flat, 2)) / 3.0f);
}

// Points of the unit sphere (apart from those converted) colored with the texture at their true
// place and normal: what a baked file should show there.
PointCloud texturedTruth(const TriplanarTexture& texture, uint64_t count) {
  PointCloud truth = test::scanOf("sphere", count, true, 0.0, 99);
  truth.colors.resize(truth.size());
  for (size_t i = 0; i < truth.size(); ++i)
    truth.colors[i] = texture.color(truth.positions[i], glm::dvec3(truth.normals[i]));
  return truth;
}

TEST(Texture, bakedAtPointsOrCornersTheSphereShowsTheTexture) {
  test::TempDir dir;
  // 16 × 16 random texels over a repeat of 2: a texel is 0.125 wide, about 7 spacings of
  // 100k points on the unit sphere (0.011).
  test::writePpm(dir / "tex.ppm", 16, 16, test::randomImage(16, 16, 5));
  const TriplanarTexture texture(readLinearImage(dir / "tex.ppm"), 2.0, 4.0);
  const PointCloud truth = texturedTruth(texture, 30000);
  const PointCloud points = test::scanOf("sphere", 100000);
  double psnr[2] = {};
  for (TextureAt at : {TextureAt::Points, TextureAt::Corners}) {
    BuildOptions options;
    options.texture = {dir / "tex.ppm", 2.0, 4.0, at};
    const test::Converted c = test::convertAndLoad(points, dir / "baked.iso", options);
    ASSERT_TRUE(c.surface.hasColors());
    EXPECT_EQ(c.report["texture"]["width"], 16);
    EXPECT_EQ(c.report["texture"]["at"], at == TextureAt::Points ? "points" : "corners");
    const nlohmann::json e = evaluateAgainstPoints(c.surface, truth);
    psnr[int(at)] = e["color_psnr_db"].get<double>();
    EXPECT_GE(e["color"]["points"].get<uint64_t>(), truth.size() * 99 / 100);
  }
  std::printf("random 16x16 texture on the sphere: %.2f dB at points, %.2f dB at corners\n",
              psnr[0], psnr[1]);
  // Random colors are 21 dB apart on average (uniform bytes: RMS difference 104): both bakes
  // must be far closer to the texture than that.
  EXPECT_GT(psnr[0], 28.0);
  EXPECT_GT(psnr[1], 28.0);
}

TEST(Texture, aTextureMultipliesThePointsOwnColors) {
  test::TempDir dir;
  test::writePpm(dir / "one.ppm", 1, 1, {188, 188, 188});  // linear 0.5
  PointCloud points = test::scanOf("sphere", 20000);
  points.colors.assign(points.size(), glm::vec3(0.2f, 0.6f, 1.0f));
  BuildOptions options;
  options.texture.image = dir / "one.ppm";
  for (TextureAt at : {TextureAt::Points, TextureAt::Corners}) {
    options.texture.at = at;
    const test::Converted c = test::convertAndLoad(points, dir / "times.iso", options);
    EXPECT_TRUE(c.report["texture"]["modulates_point_colors"].get<bool>());
    const float half = srgb8ToLinear(188);
    PointCloud expected = points;
    expected.colors.assign(points.size(), glm::vec3(0.2f, 0.6f, 1.0f) * half);
    // Uniform colors: sRGB8 quantization alone.
    EXPECT_GT(evaluateAgainstPoints(c.surface, expected)["color_psnr_db"].get<double>(), 45.0);
  }
}

// The occlusion values of a file's leaf corners that pass `keep` (at frame positions).
std::vector<float> occlusionWhere(const std::filesystem::path& path,
                                  const std::function<bool(const glm::dvec3&)>& keep) {
  const Reader reader = Reader::open(path);
  std::vector<float> out;
  for (const ChunkInfo& info : reader.chunks()) {
    const SurfaceChunk chunk = decodeSurfaceChunk(reader, info.id);
    EXPECT_EQ(chunk.leafValues.occlusion.size(), chunk.layout.leafCorners.size());
    for (size_t i = 0; i < chunk.layout.leafCorners.size(); ++i)
      if (keep(gridToFrame(chunk.layout.leafCorners[i].point)))
        out.push_back(chunk.leafValues.occlusion[i]);
  }
  return out;
}

double mean(const std::vector<float>& v) {
  double sum = 0.0;
  for (float x : v) sum += x;
  return v.empty() ? 0.0 : sum / double(v.size());
}

TEST(Occlusion, theOutsideOfASphereIsOpenAndItsInsideClosed) {
  test::TempDir dir;
  PointCloud points = test::scanOf("sphere", 40000);
  BuildOptions options;
  options.occlusion = {true, 32, 0.5};
  const nlohmann::json outside = convertToIso(points, dir / "out.iso", options);
  const std::vector<float> open = occlusionWhere(dir / "out.iso", [](auto&) { return true; });
  // Convex: no ray meets the surface again.
  EXPECT_GT(mean(open), 0.995) << outside["occlusion"].dump();
  EXPECT_GT(*std::min_element(open.begin(), open.end()), 0.9f);
  EXPECT_EQ(outside["occlusion"]["corners"].get<uint64_t>() > open.size(), true);
  // Normals inwards: the inside of a ball of radius 1, every ray meets it within 2.
  for (glm::vec3& n : points.normals) n = -n;
  options.occlusion.radius = 2.5;
  convertToIso(points, dir / "in.iso", options);
  const std::vector<float> closed = occlusionWhere(dir / "in.iso", [](auto&) { return true; });
  EXPECT_LT(mean(closed), 0.005);
  EXPECT_LT(*std::max_element(closed.begin(), closed.end()), 0.1f);
}

TEST(Occlusion, facingSheetsGiveTheAnalyticFraction) {
  // Two squares of half size 1 at z = ±0.1, normals facing each other across the gap h = 0.2.
  // Cosine-weighted rays from one meet the other within R when cos θ > h/R, so the open fraction
  // is (h/R)² far from the edges: 0.25 for R = 0.4.
  ShapeParams params;
  params.name = "sheets";
  params.gap = 0.2;
  const std::unique_ptr<Shape> sheets = makeShape(params);
  GenerateOptions generate;
  generate.count = 120000;
  PointCloud points = generateScan(*sheets, generate);
  for (glm::vec3& n : points.normals) n = -n;
  test::TempDir dir;
  BuildOptions options;
  options.occlusion = {true, 64, 0.4};
  const nlohmann::json report = convertToIso(points, dir / "gap.iso", options);
  // The frame maps world to [0, 1)³: the corners near the middle of the squares (flat sheets
  // sit inside large leaves: corners up to a leaf away project onto them).
  const Reader reader = Reader::open(dir / "gap.iso");
  const Frame frame = reader.header().frame;
  const auto world = [&](const glm::dvec3& f) {
    return glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]) + f * frame.size;
  };
  const std::vector<float> middle = occlusionWhere(dir / "gap.iso", [&](const glm::dvec3& f) {
    const glm::dvec3 p = world(f);
    return std::abs(p.x) < 0.4 && std::abs(p.y) < 0.4 && std::abs(p.z) < 0.3;
  });
  ASSERT_GT(middle.size(), 20u);
  std::printf("facing sheets: %zu corners, mean open fraction %.4f (analytic 0.25)\n",
              middle.size(), mean(middle));
  EXPECT_NEAR(mean(middle), 0.25, 0.02);
  for (float o : middle) EXPECT_NEAR(o, 0.25, 0.08);
  EXPECT_EQ(report["occlusion"]["rays_per_corner"], 64);
}

TEST(Occlusion, theBakeKeepsEveryOtherValueAndIsDeterministic) {
  test::TempDir dir;
  PointCloud points = test::scanOf("torus", 30000);
  points.colors.assign(points.size(), glm::vec3(0.3f, 0.5f, 0.7f));
  BuildOptions options;
  convertToIso(points, dir / "plain.iso", options);
  options.occlusion = {true, 16, 1.5};  // the ring's inner side sees its far side
  const nlohmann::json report = convertToIso(points, dir / "ao.iso", options);
  convertToIso(points, dir / "again.iso", options);
  EXPECT_TRUE(test::readFile(dir / "ao.iso") == test::readFile(dir / "again.iso"));
  const Reader plain = Reader::open(dir / "plain.iso"), baked = Reader::open(dir / "ao.iso");
  ASSERT_EQ(baked.header().attributes.size(), plain.header().attributes.size() + 1);
  EXPECT_EQ(baked.header().attributes.back().semantic, Semantic::Occlusion);
  ASSERT_EQ(plain.chunks().size(), baked.chunks().size());
  for (uint32_t id = 0; id < plain.chunks().size(); ++id) {
    const ChunkInfo &a = plain.chunk(id), &b = baked.chunk(id);
    EXPECT_EQ(a.parent, b.parent);
    EXPECT_EQ(a.key, b.key);
    EXPECT_EQ(a.geometricError, b.geometricError);
    const SurfaceChunk x = decodeSurfaceChunk(plain, id), y = decodeSurfaceChunk(baked, id);
    EXPECT_EQ(x.topology.childMasks, y.topology.childMasks);
    for (auto [u, v] : {std::pair{&x.leafValues, &y.leafValues}, {&x.lodValues, &y.lodValues}}) {
      EXPECT_EQ(u->distance, v->distance);
      EXPECT_EQ(u->normal, v->normal);
      EXPECT_EQ(u->color, v->color);
      EXPECT_EQ(v->occlusion.size(), v->distance.size());
    }
  }
  // A torus occludes itself inside its ring: some corners are darker than the rest.
  EXPECT_LT(report["occlusion"]["mean"].get<double>(), 0.99);
  EXPECT_GT(report["occlusion"]["mean"].get<double>(), 0.5);
}

}  // namespace
}  // namespace iso
