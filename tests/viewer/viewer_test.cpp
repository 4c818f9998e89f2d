// The viewer against references: the GPU's pictures (lavapipe in CI) against the CPU reference
// tracer's, the tracer's hits against the surface model's and the analytic sphere, streaming
// under a tiny budget against an unlimited one, and scene files.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <thread>

#include "iso/error.h"
#include "iso/points.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "iso/writer.h"
#include "pipeline/base/options.h"
#include "pipeline/io/readers.h"
#include "tests/pipeline/pipeline_support.h"
#include "viewer/asset.h"
#include "tracer/cpu_tracer.h"
#include "base/image.h"
#include "viewer/renderer.h"
#include "viewer/scene.h"
#include "viewer/streaming.h"
#include "viewer/vulkan.h"
#include "test_gpu.h"

namespace iso::test {

viewer::Gpu& testGpu() {
  static viewer::Gpu g = [] {
    viewer::GpuOptions o;
    o.validation = true;
    return viewer::createGpu(o);
  }();
  return g;
}

namespace {

using namespace iso::viewer;

struct Files {
  TempDir dir;
  std::filesystem::path sphere = dir / "sphere.iso", torus = dir / "torus.iso",
                        kitten = dir / "kitten.iso", chunked = dir / "chunked.iso";
  // With their points kept: a sphere scanned without normals, the kitten, a noisy torus, and a
  // torus in many points chunks and subsamples.
  std::filesystem::path spherePoints = dir / "sphere-points.iso",
                        kittenPoints = dir / "kitten-points.iso",
                        noisyPoints = dir / "noisy-points.iso",
                        chunkedPoints = dir / "chunked-points.iso";
  double sphereSpacing = 0, spherePointsSpacing = 0, kittenSpacing = 0, noisySpacing = 0;
  Files() {
    BuildOptions quiet;
    sphereSpacing = convertToIso(scanOf("sphere", 30000), sphere, quiet)["spacing"];
    convertToIso(scanOf("torus", 30000), torus, quiet);
    const PointCloud kittenCloud =
        readPointFile(builtPath("ISO_TEST_DATA_DIR", ISO_TEST_DATA_DIR) / "kitten_normals.xyz");
    convertToIso(kittenCloud, kitten, quiet);
    BuildOptions small;  // many chunks, to stream
    small.chunkNodes = 600;
    convertToIso(scanOf("torus", 30000), chunked, small);
    BuildOptions keep;
    keep.keepPoints = true;
    spherePointsSpacing = convertToIso(scanOf("sphere", 40000, false), spherePoints, keep)["spacing"];
    kittenSpacing = convertToIso(kittenCloud, kittenPoints, keep)["spacing"];
    noisySpacing = convertToIso(scanOf("torus", 40000, true, 0.3), noisyPoints, keep)["spacing"];
    keep.keptPointsPerChunk = 1500;
    keep.chunkNodes = 600;
    convertToIso(scanOf("torus", 30000), chunkedPoints, keep);
  }
};

const Files& files() {
  static Files f;
  return f;
}

// One Vulkan device for the whole program, validation on when the layer is installed.
Gpu& gpu() { return testGpu(); }

Scene sceneFor(const Asset& asset) {
  Scene scene;
  scene.camera = defaultCamera(asset.cells, asset.up, 40.0, 1.0);
  scene.lights.push_back(defaultLight(*scene.camera, asset.bounds));
  return scene;
}

std::vector<uint32_t> renderReference(const Asset& asset, const Scene& scene, uint32_t w,
                                      uint32_t h, const Environment* env = nullptr) {
  const CpuPool pool = buildCpuPool(asset.reader);
  const auto header = asset.reader.header();
  return renderCpu(
             pool,
             frameParams(scene, header.frame, header.maxLevel, cpuFrameSetup(asset, w, h, env)),
             env)
      .pixels;
}

struct GpuRun {
  std::vector<uint32_t> pixels;
  std::vector<uint32_t> first;  // the first frame's picture
  FrameStats stats;
  uint32_t frameCount = 0;
  bool converged = false;
  uint64_t peak = 0;  // device memory at most, from the allocator
};

RendererOptions rendererOptions(uint32_t w, uint32_t h, uint64_t vram, uint32_t framesInFlight) {
  RendererOptions o;
  o.width = w;
  o.height = h;
  o.vram = vram;
  o.uploadBytes = 64 << 10;  // a few chunks a frame, so that streaming takes frames
  o.framesInFlight = framesInFlight;
  return o;
}

// Frames of `scene` until one converges (frames in flight go on while the renderer learns it).
void renderUntilConverged(Renderer& renderer, const Asset& asset, const Scene& scene,
                          uint32_t maxFrames, GpuRun& run) {
  const auto header = asset.reader.header();
  for (uint32_t f = 0; f < maxFrames; ++f) {
    renderFrame(renderer, frameParams(scene, header.frame, header.maxLevel, renderer.setup()));
    if (run.frameCount++ == 0) run.first = renderer.pixels();
    if (!renderer.converged()) continue;
    renderer.finish();  // the last frame in flight is the one shown
    if (renderer.converged()) {
      run.converged = true;
      break;
    }
  }
  run.pixels = renderer.pixels();
  run.stats = renderer.stats();
}

// The renderer's choices of kernel (RendererOptions).
struct Kernel {
  bool flat = false;
  uint32_t workgroup = 64;
  bool oneKernel = false;
  bool tileCones = true;
};

GpuRun renderGpu(const Asset& asset, const Scene& scene, uint32_t w, uint32_t h, uint64_t vram,
                 const Environment* env = nullptr, uint32_t maxFrames = 200,
                 uint32_t framesInFlight = 1, const Kernel& kernel = {}) {
  Gpu& g = gpu();
  const uint64_t before = g.memoryInUse;
  g.memoryPeak = before;
  GpuRun run;
  {
    RendererOptions o = rendererOptions(w, h, vram, framesInFlight);
    o.flatTraversal = kernel.flat;
    o.workgroupSize = kernel.workgroup;
    o.oneKernel = kernel.oneKernel;
    o.tileCones = kernel.tileCones;
    o.caustics = scene.caustics > 0;
    Renderer renderer(g, asset, env, o);
    renderUntilConverged(renderer, asset, scene, maxFrames, run);
  }
  run.peak = g.memoryPeak - before;
  EXPECT_EQ(g.validationErrors->load(), 0u) << "Vulkan validation errors";
  return run;
}

// Pixels whose channels differ by more than `threshold` in any of R, G, B.
double differing(const std::vector<uint32_t>& a, const std::vector<uint32_t>& b,
                 int threshold = 8) {
  EXPECT_EQ(a.size(), b.size());
  size_t n = 0;
  for (size_t i = 0; i < a.size(); ++i)
    for (int c = 0; c < 3; ++c)
      if (std::abs(int(a[i] >> (8 * c) & 0xFF) - int(b[i] >> (8 * c) & 0xFF)) > threshold) {
        ++n;
        break;
      }
  return double(n) / double(a.size());
}

TEST(ViewerGolden, theGpuAndTheCpuReferenceDrawTheSamePictures) {
  // Metric: at most 0.5 % of the pixels differ by more than 8/255 in a channel.
  const uint32_t w = 160, h = 120;
  for (const auto& file : {files().sphere, files().torus, files().kitten}) {
    SCOPED_TRACE(file.filename().string());
    const auto asset = Asset::open(file);
    Scene scene = sceneFor(*asset);
    const auto gpuPicture = renderGpu(*asset, scene, w, h, uint64_t(1) << 30);
    const auto cpuPicture = renderReference(*asset, scene, w, h);
    EXPECT_TRUE(gpuPicture.converged);
    const double differ = differing(gpuPicture.pixels, cpuPicture);
    std::printf("%s: %.4f %% of the pixels differ by more than 8/255\n", file.filename().c_str(),
                100 * differ);
    EXPECT_LE(differ, 0.005);
    // Not a blank picture: the framed surface covers a good part of it, lit unevenly.
    size_t lit = 0, dark = 0;
    for (uint32_t p : cpuPicture) {
      const int g = int(p >> 8 & 0xFF);
      lit += g > 150;
      dark += g < 90;
    }
    EXPECT_GT(lit, cpuPicture.size() / 50);
    EXPECT_GT(dark, cpuPicture.size() / 100);
  }
}

TEST(ViewerGolden, shadowsReflectionsRefractionsAreaLightsAndEnvironmentMapsAgreeToo) {
  const uint32_t w = 128, h = 96;
  const auto asset = Asset::open(files().torus);
  Scene scene = sceneFor(*asset);
  LightSpec area = scene.lights[0];
  area.area = true;
  area.samples = 8;
  const double r = 0.3 * (asset->bounds.hi[0] - asset->bounds.lo[0]);
  area.u = {r, 0, 0};
  area.v = {0, 0, r};
  scene.lights = {area};
  scene.material.reflectivity = 0.3f;
  scene.material.transparency = 0.3f;
  scene.samples = 2;
  // An environment map written as a PNG and read back through OpenImageIO: four colored bands
  // of longitude, brighter toward the top.
  TempDir dir;
  const uint32_t ew = 64, eh = 32;
  std::vector<uint32_t> bands(ew * eh);
  for (uint32_t y = 0; y < eh; ++y)
    for (uint32_t x = 0; x < ew; ++x) {
      const uint32_t v = 255 - 6 * y, band = x * 4 / ew;
      bands[y * ew + x] = (band == 0 ? v : 40) | (band == 1 ? v : 40) << 8 |
                          (band == 2 ? v : 40) << 16 | 0xFF000000u;
    }
  writeRgba8Image(dir / "sky.png", ew, eh, bands);
  const Environment env = loadEnvironment(dir / "sky.png");
  ASSERT_EQ(env.width, ew);
  const auto gpuPicture = renderGpu(*asset, scene, w, h, uint64_t(1) << 30, &env);
  const auto cpuPicture = renderReference(*asset, scene, w, h, &env);
  const double differ = differing(gpuPicture.pixels, cpuPicture);
  std::printf("effects: %.4f %% of the pixels differ by more than 8/255\n", 100 * differ);
  EXPECT_LE(differ, 0.005);
  // And the effects change the picture: without them and the map it differs a lot.
  Scene plain = sceneFor(*asset);
  EXPECT_GT(differing(renderReference(*asset, plain, w, h), cpuPicture), 0.3);
}

TEST(ViewerGolden, bakedTexturesAndAmbientOcclusionAgreeAndOcclusionDarkensTheAmbient) {
  // A torus textured with a 2 × 2 image (red, green; blue, white), once without and once with
  // occlusion baked within its whole size (the ring's inside sees its far side).
  TempDir dir;
  writeRgba8Image(dir / "quad.png", 2, 2, {0xFF0000FFu, 0xFF00FF00u, 0xFFFF0000u, 0xFFFFFFFFu});
  BuildOptions options;
  options.texture = {dir / "quad.png", 1.0, 4.0, TextureAt::Corners};
  const PointCloud torus = scanOf("torus", 30000);
  convertToIso(torus, dir / "textured.iso", options);
  options.occlusion = {true, 32, 2.0};
  convertToIso(torus, dir / "occluded.iso", options);
  const uint32_t w = 128, h = 96;
  std::vector<uint32_t> pictures[2];
  for (int i = 0; i < 2; ++i) {
    const auto asset = Asset::open(dir / (i == 0 ? "textured.iso" : "occluded.iso"));
    EXPECT_TRUE(asset->blob.colors);
    EXPECT_EQ(asset->blob.occlusion, i == 1);
    Scene scene = sceneFor(*asset);
    scene.ambient = {0.8f, 0.8f, 0.8f};
    scene.lights[0].color = {0.2f, 0.2f, 0.2f};
    pictures[i] = renderReference(*asset, scene, w, h);
    const double differ =
        differing(renderGpu(*asset, scene, w, h, uint64_t(1) << 30).pixels, pictures[i]);
    std::printf("baked %s: %.4f %% of the pixels differ by more than 8/255\n",
                i == 0 ? "texture" : "texture and occlusion", 100 * differ);
    EXPECT_LE(differ, 0.005);
  }
  // The texture's colors show: pixels mostly red, mostly green and mostly blue.
  size_t red = 0, green = 0, blue = 0;
  for (uint32_t p : pictures[0]) {
    const int r = int(p & 0xFF), g = int(p >> 8 & 0xFF), b = int(p >> 16 & 0xFF);
    red += r > g + 60 && r > b + 60;
    green += g > r + 60 && g > b + 60;
    blue += b > r + 60 && b > g + 60;
  }
  EXPECT_GT(std::min({red, green, blue}), pictures[0].size() / 200)
      << red << " " << green << " " << blue;
  // Occlusion only darkens, and seen from above it darkens the ring's inner side: about 3 % of
  // the picture.
  size_t darker = 0, lighter = 0;
  for (size_t i = 0; i < pictures[0].size(); ++i) {
    const int a = int(pictures[0][i] >> 8 & 0xFF), b = int(pictures[1][i] >> 8 & 0xFF);
    darker += b < a - 8;
    lighter += b > a + 2;
  }
  EXPECT_GT(darker, pictures[0].size() / 100);
  EXPECT_EQ(lighter, 0u);
}

// A ball over a plane under a point light, its light baked without bounces (iso bake): drawn with
// the baked irradiance (no shadow rays) the picture is the live one's but for the light map's
// interpolation across the leaves; `both` adds the baked diffuse light to the live one; the GPU
// draws what the CPU reference draws.
TEST(ViewerGolden, bakedLightingDrawsTheLiveLightsDiffuseTermAndAgreesOnTheGpu) {
  TempDir dir;
  PointCloud points = scanOf("plane", 30000);
  ShapeParams ball;
  ball.radius = 0.3;
  ball.center = {0.0, 0.0, 0.45};
  const PointCloud sphere = scanOf(ball, 12000);
  for (size_t i = 0; i < sphere.size(); ++i) appendPoint(points, sphere, i);
  BuildOptions options;
  options.maxTestedEdge = 4.0;  // a light map as fine as the shadow's edge
  BakeLight light;
  light.position = {0.6, -0.5, 1.6};
  options.lighting.enabled = true;
  options.lighting.lights = {light};
  options.lighting.bounces = 0;
  convertToIso(points, dir / "lit.iso", options);
  const auto asset = Asset::open(dir / "lit.iso");
  ASSERT_TRUE(asset->blob.irradiance);
  Scene scene = sceneFor(*asset);
  scene.camera->eye = {0.0, -2.2, 1.4};
  scene.camera->target = {0.0, 0.0, 0.1};
  scene.camera->up = {0.0, 0.0, 1.0};
  scene.lights = {LightSpec{.position = {0.6, -0.5, 1.6}}};
  scene.material.specular = 0.0f;
  scene.ambient = {0.05f, 0.05f, 0.05f};
  const uint32_t w = 160, h = 120;
  std::vector<uint32_t> pictures[3];
  const Lighting modes[3] = {Lighting::Live, Lighting::Baked, Lighting::Both};
  for (int i = 0; i < 3; ++i) {
    scene.lighting = modes[i];
    pictures[i] = renderReference(*asset, scene, w, h);
  }
  // Baked against live: the same picture but where the light map interpolates across a shadow's
  // edge (a leaf or two wide).
  double sum = 0.0;
  for (size_t i = 0; i < pictures[0].size(); ++i)
    sum += std::abs(int(pictures[0][i] >> 8 & 0xFF) - int(pictures[1][i] >> 8 & 0xFF));
  const double differ = differing(pictures[0], pictures[1]);
  std::printf("baked against live lighting: %.3f %% of the pixels differ by more than 8/255, "
              "mean difference %.3f/255\n",
              100 * differ, sum / double(pictures[0].size()));
  EXPECT_LT(differ, 0.03);
  EXPECT_LT(sum / double(pictures[0].size()), 1.5);
  // Both: the diffuse light twice where the light reaches (a tenth of the picture at least),
  // nothing darker anywhere.
  size_t brighter = 0, darker = 0;
  for (size_t i = 0; i < pictures[0].size(); ++i) {
    const int live = int(pictures[0][i] >> 8 & 0xFF), both = int(pictures[2][i] >> 8 & 0xFF);
    brighter += both > live + 20;
    darker += both < live - 1;
  }
  EXPECT_GT(brighter, pictures[0].size() / 10);
  EXPECT_EQ(darker, 0u);
  // The GPU (streaming the lighting with the surface) draws what the CPU draws.
  for (int i = 1; i < 3; ++i) {
    scene.lighting = modes[i];
    const double gpuDiffer =
        differing(renderGpu(*asset, scene, w, h, uint64_t(1) << 30).pixels, pictures[i]);
    std::printf("%s lighting: %.4f %% of the GPU's pixels differ by more than 8/255\n",
                i == 1 ? "baked" : "both", 100 * gpuDiffer);
    EXPECT_LE(gpuDiffer, 0.002);
  }
}

// An open sheet (a plane turned out of the axes) seen from behind, where the signed distance is
// negative: the viewer shows that side (shaded with the flipped normal), tints it on request, or
// hides it, and the GPU draws what the CPU reference draws.
TEST(ViewerGolden, anOpenSheetSeenFromBehindIsShownTintedOrHidden) {
  TempDir dir;
  const ShapeParams plane = turnedShape("plane");
  const std::unique_ptr<Shape> shape = makeShape(plane);
  convertToIso(scanOf(plane, 20000), dir / "plane.iso", BuildOptions{});
  const auto asset = Asset::open(dir / "plane.iso");
  // The plane's normal is +z turned the same way.
  const glm::dvec3 n = shape->closest(glm::dvec3(0.0, 0.0, 1.0)).normal;
  const uint32_t w = 96, h = 96;
  std::vector<uint32_t> pictures[3];
  const BackFaces modes[3] = {BackFaces::Show, BackFaces::Tint, BackFaces::Hide};
  for (int side = 0; side < 2; ++side) {  // from the front, then from behind
    for (int m = 0; m < 3; ++m) {
      Scene scene;
      const glm::dvec3 eye = (side == 0 ? 4.0 : -4.0) * n + glm::dvec3(0.3, 0.2, 0.0);
      scene.camera = Camera{eye, {0, 0, 0}, {0, 1, 0}, 40.0};
      scene.lights.push_back(defaultLight(*scene.camera, asset->bounds));
      scene.backFaces = modes[m];
      pictures[m] = renderReference(*asset, scene, w, h);
      const double differ =
          differing(renderGpu(*asset, scene, w, h, uint64_t(1) << 30).pixels, pictures[m]);
      EXPECT_LE(differ, 0.005) << "side " << side << ", mode " << m;
    }
    // Showing or hiding: the sheet covers a good part of the picture from either side.
    const double covered = differing(pictures[0], pictures[2]);
    const double tinted = differing(pictures[0], pictures[1]);
    if (side == 0) {  // the front: the same whatever the mode
      EXPECT_EQ(covered, 0.0);
      EXPECT_EQ(tinted, 0.0);
    } else {
      EXPECT_GT(covered, 0.2);
      EXPECT_GT(tinted, 0.2);
      // The tint multiplies the color by (1, 0.45, 0.35): red dominates where it shows.
      size_t red = 0;
      for (size_t i = 0; i < pictures[1].size(); ++i) {
        const uint32_t p = pictures[1][i];
        red += pictures[1][i] != pictures[0][i] && int(p & 0xFF) > int(p >> 8 & 0xFF) + 20;
      }
      EXPECT_GT(double(red), 0.9 * tinted * double(pictures[1].size()));
    }
  }
}

// The file again with its distances stored as float32: the same decoded values, another record
// layout on the GPU (float32 distances, a specialization constant of the pipeline).
std::filesystem::path withFloatDistances(const std::filesystem::path& file,
                                         const std::filesystem::path& out) {
  const Reader reader = Reader::open(file);
  FileHeader header = reader.header();
  for (AttributeDesc& a : header.attributes)
    if (a.semantic == Semantic::SignedDistance) a = {a.semantic, Encoding::Float32, 1, a.scale};
  Writer writer(out, header);
  for (const ChunkInfo& c : reader.chunks()) {
    const SurfaceChunk chunk = decodeSurfaceChunk(reader, c.id);
    writer.addChunk({c.kind, c.level, c.key, c.parent, c.pointCount, c.nodeCount, c.leafCount,
                     c.geometricError, Codec::Zstd},
                    encodeSurfaceChunk(chunk.topology, chunk.layout, header.attributes,
                                       chunk.leafValues, chunk.lodValues));
  }
  writer.setMetadata(std::string(reader.metadata()));
  writer.finish();
  return out;
}

TEST(ViewerGolden, float32DistancesDrawTheSamePictureAsTheirSnorm8Codes) {
  TempDir dir;
  const auto codes = Asset::open(files().torus);
  const auto floats = Asset::open(withFloatDistances(files().torus, dir / "float.iso"));
  ASSERT_FALSE(codes->blob.floatDistances);
  ASSERT_TRUE(floats->blob.floatDistances);
  const Scene scene = sceneFor(*codes);
  const uint32_t w = 128, h = 96;
  const std::vector<uint32_t> reference = renderReference(*codes, scene, w, h);
  EXPECT_EQ(differing(renderReference(*floats, scene, w, h), reference, 0), 0.0);
  EXPECT_LE(differing(renderGpu(*floats, scene, w, h, uint64_t(1) << 30).pixels, reference), 0.005);
}

// Camera rays of a frame (frame units), traced one by one: the first hit's t per pixel, or a
// negative value for sky.
std::vector<float> hitDistances(const CpuPool& pool, const gpu::FrameParams& p) {
  std::vector<float> t(size_t(p.image.x) * p.image.y, -1.0f);
  const glm::vec3 eye(p.eye), right(p.right), up(p.up), forward(p.forward);
  for (uint32_t y = 0; y < p.image.y; ++y)
    for (uint32_t x = 0; x < p.image.x; ++x) {
      const float sx = 2.0f * (float(x) + 0.5f) / float(p.image.x) - 1.0f;
      const float sy = 1.0f - 2.0f * (float(y) + 0.5f) / float(p.image.y);
      const auto hit = traceCpu(pool, p, eye, glm::normalize(forward + sx * right + sy * up));
      if (hit) t[size_t(y) * p.image.x + x] = hit->t;
    }
  return t;
}

TEST(ViewerGolden, everyLoopShapeAndWorkgroupSizeDrawsTheSamePicture) {
  // The tracer's two loop shapes do the same arithmetic in the same order, and tiles of any size
  // cover the picture: the pictures are the same bytes, on the GPU and on the CPU.
  const auto asset = Asset::open(files().torus);
  Scene scene = sceneFor(*asset);
  scene.material.reflectivity = 0.3f;
  const uint32_t w = 100, h = 70;  // not a multiple of any tile
  const std::vector<uint32_t> reference = renderGpu(*asset, scene, w, h, uint64_t(1) << 30).pixels;
  for (const bool flat : {false, true})
    for (const uint32_t workgroup : {8u, 32u, 64u, 256u}) {
      if (!flat && workgroup == 64) continue;
      const GpuRun run =
          renderGpu(*asset, scene, w, h, uint64_t(1) << 30, nullptr, 200, 1, {flat, workgroup});
      EXPECT_TRUE(run.converged);
      EXPECT_EQ(run.pixels, reference) << (flat ? "flat" : "nested") << ", workgroup " << workgroup;
    }
  const CpuPool pool = buildCpuPool(asset->reader);
  const auto header = asset->reader.header();
  FrameSetup setup = cpuFrameSetup(*asset, w, h, nullptr);
  const std::vector<uint32_t> nested =
      renderCpu(pool, frameParams(scene, header.frame, header.maxLevel, setup), nullptr).pixels;
  setup.flatTraversal = true;
  EXPECT_EQ(
      renderCpu(pool, frameParams(scene, header.frame, header.maxLevel, setup), nullptr).pixels,
      nested);
  EXPECT_LE(differing(reference, nested), 0.005);
}

TEST(ViewerGolden, theWavefrontDrawsWhatTheOneKernelDraws) {
  // A frame of one sample a pixel whose hits leave no refracted rays runs as a wavefront: the
  // camera rays, then the queued hits' shading, then, bounce after bounce, the mirror rays those
  // hits queued and their hits' shading, with the one kernel's statements in its order: the same
  // bytes and the same rays as one kernel (--one-kernel). Here with back faces tinted, an area
  // light's jittered shadow rays (the random state goes on from hit to hit) and tiles that do not
  // divide the picture: a reflectivity that only scales the local shading (no bounces), bounces
  // without a reflectivity, mirror rays of one and of three bounces; and frames that run as one
  // kernel either way (refracted rays, two samples a pixel).
  TempDir dir;
  const ShapeParams plane = turnedShape("plane");
  const std::unique_ptr<Shape> shape = makeShape(plane);
  convertToIso(scanOf(plane, 20000), dir / "plane.iso", BuildOptions{});
  const glm::dvec3 n = shape->closest(glm::dvec3(0.0, 0.0, 1.0)).normal;
  const uint32_t w = 100, h = 70;
  for (const auto& file : {dir / "plane.iso", files().torus}) {
    const auto asset = Asset::open(file);
    Scene base = sceneFor(*asset);
    if (file == dir / "plane.iso") {  // from behind, half of the picture sky
      base.camera = Camera{-3.0 * n + glm::dvec3(0.3, 0.2, 0.0), {0, 0, 0}, {0, 1, 0}, 50.0};
      base.backFaces = BackFaces::Tint;
    }
    LightSpec area = defaultLight(*base.camera, asset->bounds);
    area.area = true;
    area.samples = 4;
    area.u = {0.5, 0, 0};
    area.v = {0, 0, 0.5};
    base.lights = {area};
    struct Case {
      float reflectivity, transparency;
      int bounces, samples;
      bool wavefront;
    };
    for (const Case c : {Case{0.3f, 0.0f, 0, 1, true}, Case{0.0f, 0.0f, 2, 1, true},
                         Case{0.3f, 0.0f, 1, 1, true}, Case{0.6f, 0.0f, 3, 1, true},
                         Case{0.3f, 0.3f, 2, 1, false}, Case{0.0f, 0.0f, 0, 2, false}}) {
      SCOPED_TRACE(file.filename().string() + ", reflectivity " + std::to_string(c.reflectivity) +
                   ", transparency " + std::to_string(c.transparency) + ", bounces " +
                   std::to_string(c.bounces) + ", samples " + std::to_string(c.samples));
      Scene scene = base;
      scene.material.reflectivity = c.reflectivity;
      scene.material.transparency = c.transparency;
      scene.bounces = c.bounces;
      scene.samples = c.samples;
      const GpuRun one = renderGpu(*asset, scene, w, h, uint64_t(1) << 30, nullptr, 200, 1,
                                   {.workgroup = 32, .oneKernel = true});
      const GpuRun two =
          renderGpu(*asset, scene, w, h, uint64_t(1) << 30, nullptr, 200, 1, {.workgroup = 32});
      EXPECT_FALSE(one.stats.twoPasses);
      EXPECT_EQ(two.stats.twoPasses, c.wavefront);
      const bool mirrors = c.reflectivity > 0.0f && c.bounces > 0;
      EXPECT_EQ(two.stats.mirrorBounces, c.wavefront && mirrors ? uint32_t(c.bounces) : 0u);
      EXPECT_TRUE(two.converged);
      EXPECT_EQ(differing(two.pixels, one.pixels, 0), 0.0);
      EXPECT_EQ(two.stats.rays.primary, uint64_t(w) * h * uint64_t(c.samples));
      EXPECT_EQ(two.stats.rays.primary, one.stats.rays.primary);
      EXPECT_EQ(two.stats.rays.shadow, one.stats.rays.shadow);
      EXPECT_EQ(two.stats.rays.secondary, one.stats.rays.secondary);
      EXPECT_GT(one.stats.rays.shadow, 0u);
      EXPECT_EQ(one.stats.rays.secondary > 0, mirrors || (c.transparency > 0 && c.bounces > 0));
      // Three bounces: some mirror rays hit the surface again (the torus sees itself).
      if (c.bounces == 3 && file == files().torus) {
        EXPECT_GT(one.stats.rays.secondary, 2 * uint64_t(w) * h / 20);
      }
    }
    // Surface and sky both in the picture: the queue held some of the pixels.
    const auto header = asset->reader.header();
    const std::vector<float> t = hitDistances(
        buildCpuPool(asset->reader),
        frameParams(base, header.frame, header.maxLevel, cpuFrameSetup(*asset, w, h, nullptr)));
    const size_t sky = size_t(std::count_if(t.begin(), t.end(), [](float d) { return d < 0.0f; }));
    EXPECT_GT(sky, t.size() / 20);
    EXPECT_LT(sky, t.size() * 19 / 20);
  }
}

TEST(ViewerGolden, aWavefrontFrameLargerThanAWaveRunsInWaves) {
  // 640×480 in tiles of 8 invocations: 38,400 tiles, more than a wave (2^17 pixels) holds, so the
  // frame runs as three waves of all passes, mirror rays included; the same bytes as one kernel.
  const auto asset = Asset::open(files().torus);
  Scene scene = sceneFor(*asset);
  scene.material.reflectivity = 0.3f;
  scene.bounces = 1;
  const uint32_t w = 640, h = 480;
  const GpuRun one = renderGpu(*asset, scene, w, h, uint64_t(1) << 30, nullptr, 200, 1,
                               {.workgroup = 8, .oneKernel = true});
  const GpuRun two =
      renderGpu(*asset, scene, w, h, uint64_t(1) << 30, nullptr, 200, 1, {.workgroup = 8});
  EXPECT_TRUE(two.stats.twoPasses);
  EXPECT_EQ(two.stats.mirrorBounces, 1u);
  EXPECT_EQ(differing(two.pixels, one.pixels, 0), 0.0);
  EXPECT_EQ(two.stats.rays.shadow, one.stats.rays.shadow);
  EXPECT_EQ(two.stats.rays.secondary, one.stats.rays.secondary);
}

TEST(ViewerLod, nodesDrawnInPlaceOfTheirChildrenLeaveNoCracksBesideFinerOnes) {
  // The torus in many chunks, small on the screen from several sides, and a turned open plane
  // seen at a grazing angle (distances vary tenfold along it), drawn with coarser nodes wherever
  // their error covers less than 3 pixels (and they span at most 2). Every pixel whose 3×3
  // neighbourhood shows the surface at the finest level still shows it, at about the same depth:
  // no ray passes between a coarse node and its finer neighbour to the surface behind (camera rays
  // see both sides, so a crack shows the far side, not the sky). The seam rule catches the sign
  // change across their common face. And coarse nodes were drawn (the hits moved).
  TempDir dir;
  BuildOptions small;
  small.chunkNodes = 600;
  convertToIso(scanOf(turnedShape("plane"), 60000), dir / "plane.iso", small);
  size_t interior = 0, holes = 0, moved = 0, cracks = 0;
  for (const auto& file : {files().chunked, dir / "plane.iso"}) {
    const auto asset = Asset::open(file);
    const CpuPool pool = buildCpuPool(asset->reader);
    const bool plane = file.filename() == "plane.iso";
    for (int view = 0; view < (plane ? 1 : 8); ++view) {
      Scene scene = sceneFor(*asset);
      const Vec3d centre = 0.5 * (asset->bounds.lo + asset->bounds.hi);
      scene.camera->target = centre;
      if (plane) {  // low over the plane (turned 25° about x, 15° about y), looking along it
        const Vec3d normal(-std::sin(15 * M_PI / 180) * std::cos(25 * M_PI / 180),
                           std::cos(15 * M_PI / 180) * std::cos(25 * M_PI / 180),
                           std::sin(25 * M_PI / 180));
        scene.camera->eye = centre + 0.25 * normal + Vec3d(3.0, 0.0, 0.0);
        scene.camera->up = normal;
      } else {
        const double a = view * M_PI / 4;
        scene.camera->eye = centre + Vec3d(3.0 * std::cos(a), 1.5, 3.0 * std::sin(a));
      }
      const uint32_t w = plane ? 120 : 48, h = plane ? 90 : 36;
      const auto header = asset->reader.header();
      auto params =
          frameParams(scene, header.frame, header.maxLevel, cpuFrameSetup(*asset, w, h, nullptr));
      params.lod.x = -1.0f;
      const std::vector<float> finest = hitDistances(pool, params);
      params.lod.x = 3.0f;
      const std::vector<float> coarse = hitDistances(pool, params);
      for (uint32_t y = 1; y + 1 < h; ++y)
        for (uint32_t x = 1; x + 1 < w; ++x) {
          bool surrounded = true;
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx)
              surrounded = surrounded && finest[(y + dy) * w + (x + dx)] >= 0.0f;
          const size_t i = size_t(y) * w + x;
          if (!surrounded) continue;
          ++interior;
          holes += coarse[i] < 0.0f;
          moved += coarse[i] >= 0.0f && std::abs(coarse[i] - finest[i]) > 1e-5f;
          // Deeper than 10 pixels' width at that distance: through to another surface.
          cracks += coarse[i] - finest[i] > 10.0f * params.eye.w * finest[i];
        }
    }
  }
  std::printf("%zu interior pixels, %zu holes, %zu cracks, %zu hits moved by coarser nodes\n",
              interior, holes, cracks, moved);
  EXPECT_GT(interior, 2000u);
  EXPECT_EQ(holes, 0u);
  EXPECT_EQ(cracks, 0u);
  EXPECT_GT(moved, interior / 10);
}

// One view of the cone test: the tile starts of a frame checked against each pixel's ray traced
// alone from the eye; the picture and the rays with tile cones on and off compared.
struct ConeCheck {
  size_t tiles = 0, hitTiles = 0, skipping = 0, skyTiles = 0, early = 0, skyHits = 0;
};

void checkCones(const CpuPool& pool, gpu::FrameParams p, ConeCheck& check) {
  p.options.x |= gpu::kOptionTileCones;
  const CpuFrame cones = renderCpu(pool, p, nullptr);
  gpu::FrameParams off = p;
  off.options.x &= ~gpu::kOptionTileCones;
  // Neither cones nor the box of the nodes that are not empty (rays clipped to it) change them.
  off.contentLo = glm::vec4(0.0f);
  off.contentHi = glm::vec4(1.0f);
  const CpuFrame eye = renderCpu(pool, off, nullptr);
  EXPECT_EQ(differing(cones.pixels, eye.pixels, 0), 0.0);
  EXPECT_EQ(cones.rays.primary, eye.rays.primary);
  EXPECT_EQ(cones.rays.shadow, eye.rays.shadow);
  EXPECT_EQ(cones.rays.secondary, eye.rays.secondary);
  const std::vector<float> hits = hitDistances(pool, p);
  const uint32_t w = p.image.x, h = p.image.y;
  for (uint32_t y0 = 0; y0 < h; y0 += 8)
    for (uint32_t x0 = 0; x0 < w; x0 += 8) {
      const uint32_t x1 = std::min(x0 + 8, w), y1 = std::min(y0 + 8, h);
      const float start = tileStartCpu(pool, p, x0, y0, x1, y1);
      EXPECT_EQ(tileStartCpu(pool, off, x0, y0, x1, y1), 0.0f);
      float nearest = 1e30f;
      for (uint32_t y = y0; y < y1; ++y)
        for (uint32_t x = x0; x < x1; ++x)
          if (hits[size_t(y) * w + x] >= 0.0f) nearest = std::min(nearest, hits[size_t(y) * w + x]);
      ++check.tiles;
      check.early += nearest < start;
      // Cones of one pixel too: narrower than the nodes that coarser levels draw.
      for (uint32_t y = y0; y < y1; ++y)
        for (uint32_t x = x0; x < x1; ++x) {
          const float t = hits[size_t(y) * w + x];
          check.early += t >= 0.0f && t < tileStartCpu(pool, p, x, y, x + 1, y + 1);
        }
      if (start >= 1e29f) {
        ++check.skyTiles;
        check.skyHits += nearest < 1e30f;
      } else if (nearest < 1e30f) {
        ++check.hitTiles;
        check.skipping += start >= 0.5f * nearest;
      }
    }
}

TEST(ViewerCones, aTilesCameraRaysStartBeforeAnyOfThemMeetsTheSurfaceAndDrawTheSamePicture) {
  // The camera rays of each 8×8 tile start where a cone around them first meets a node that is
  // not empty (shaders/cone.h). Against each pixel's ray traced alone from the eye: no hit before
  // its tile's start, and tiles whose cone meets nothing show only sky. The pictures and the rays
  // of every kind are the same with and without cones (and without the clip of every ray to the
  // box of the nodes that are not empty): with coarser nodes drawn, chunks not
  // resident, the eye inside the surface's box, reflections and supersampling. And the cones save
  // most of the way: in 3/4 of the tiles with a hit or more, at least half of the distance to the
  // nearest one.
  ConeCheck check;
  const auto chunked = Asset::open(files().chunked);
  const auto header = chunked->reader.header();
  const CpuPool all = buildCpuPool(chunked->reader);
  ASSERT_GT(all.chunks.size(), 4u);
  // The torus is flat: its box is a fraction of the root cube.
  const glm::vec3 extent = chunked->contentHi - chunked->contentLo;
  EXPECT_LT(extent.x * extent.y * extent.z, 0.5f);
  for (int view = 0; view < 4; ++view) {
    Scene scene = sceneFor(*chunked);
    const Vec3d centre = 0.5 * (chunked->bounds.lo + chunked->bounds.hi);
    const double a = view * M_PI / 2 + 0.3;
    scene.camera->eye = centre + Vec3d(2.5 * std::cos(a), 1.2, 2.5 * std::sin(a));
    scene.lodPixels = view < 2 ? 3.0f : 0.0f;
    scene.shadows = view % 2 == 0;
    checkCones(
        all,
        frameParams(scene, header.frame, header.maxLevel, cpuFrameSetup(*chunked, 97, 65, nullptr)),
        check);
  }
  const ConeCheck orbit = check;
  // The top chunk alone: rays draw the cut nodes' patches.
  const CpuPool top =
      buildCpuPool(chunked->reader, [](const ChunkInfo& c) { return c.parent == kNoParent; });
  checkCones(top,
             frameParams(sceneFor(*chunked), header.frame, header.maxLevel,
                         cpuFrameSetup(*chunked, 64, 48, nullptr)),
             check);
  // The eye inside the kitten's box; reflections and two samples a pixel.
  const auto kitten = Asset::open(files().kitten);
  const auto kittenHeader = kitten->reader.header();
  Scene close = sceneFor(*kitten);
  close.camera->eye = close.camera->target + 0.35 * (kitten->bounds.hi - kitten->bounds.lo);
  close.material.reflectivity = 0.3f;
  close.bounces = 2;
  close.samples = 2;
  checkCones(buildCpuPool(kitten->reader),
             frameParams(close, kittenHeader.frame, kittenHeader.maxLevel,
                         cpuFrameSetup(*kitten, 64, 48, nullptr)),
             check);
  std::printf(
      "%zu tiles: %zu with hits (%zu of the orbit's %zu skip half the way or more), %zu "
      "of sky\n",
      check.tiles, check.hitTiles, orbit.skipping, orbit.hitTiles, check.skyTiles);
  EXPECT_EQ(check.early, 0u);
  EXPECT_EQ(check.skyHits, 0u);
  EXPECT_GT(check.skyTiles, 0u);
  EXPECT_GT(orbit.hitTiles, 100u);
  EXPECT_GE(4 * orbit.skipping, 3 * orbit.hitTiles);
  // The GPU draws the same picture with and without them.
  const Scene scene = sceneFor(*chunked);
  EXPECT_EQ(renderGpu(*chunked, scene, 100, 70, uint64_t(1) << 30).pixels,
            renderGpu(*chunked, scene, 100, 70, uint64_t(1) << 30, nullptr, 200, 1,
                      {false, 64, false, false})
                .pixels);
}

TEST(ViewerTracer, hitsAgreeWithTheSurfaceModelAndTheAnalyticSphere) {
  const auto asset = Asset::open(files().sphere);
  const SurfaceModel model = SurfaceModel::load(asset->reader);
  const CpuPool pool = buildCpuPool(asset->reader);
  const Frame& frame = asset->reader.header().frame;
  const Scene scene = sceneFor(*asset);
  auto params = frameParams(scene, frame, asset->reader.header().maxLevel,
                            cpuFrameSetup(*asset, 64, 64, nullptr));
  params.lod.x = -1.0f;  // the finest leaves everywhere, as SurfaceModel's
  const double cell = std::ldexp(1.0, -int(asset->reader.header().maxLevel));
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(-0.9, 0.9);
  int hits = 0, agree = 0, onSphere = 0;
  const int rays = 2000;
  for (int i = 0; i < rays; ++i) {
    // From a sphere of radius 3 around the unit sphere toward a point well inside it (world
    // units).
    Vec3 dir{normal(rng), normal(rng), normal(rng)};
    const double n = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    Vec3 originWorld{3 * dir[0] / n, 3 * dir[1] / n, 3 * dir[2] / n};
    Vec3 aim{uniform(rng), uniform(rng), uniform(rng)};
    if (aim[0] * aim[0] + aim[1] * aim[1] + aim[2] * aim[2] > 0.8 * 0.8) {
      --i;  // aim inside a ball of radius 0.8: no grazing rays
      continue;
    }
    Vec3 d{aim[0] - originWorld[0], aim[1] - originWorld[1], aim[2] - originWorld[2]};
    const double dn = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (double& c : d) c /= dn;
    Vec3 o;
    for (int k = 0; k < 3; ++k) o[k] = (originWorld[k] - frame.origin[k]) / frame.size;
    const auto mine =
        traceCpu(pool, params, glm::vec3(o[0], o[1], o[2]), glm::vec3(d[0], d[1], d[2]));
    const auto theirs = model.intersect(o, d, 0.0, 1e9);
    ASSERT_EQ(mine.has_value(), theirs.has_value()) << "ray " << i;
    if (!mine) continue;
    ++hits;
    // The same surface: t within a tenth of the finest cell (float against double).
    agree += std::abs(mine->t - theirs->t) <= 0.1 * cell;
    // And the unit sphere: within half a point spacing.
    double radius2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double p = frame.origin[k] + (o[k] + mine->t * d[k]) * frame.size;
      radius2 += p * p;
    }
    onSphere += std::abs(std::sqrt(radius2) - 1.0) <= 0.5 * files().sphereSpacing;
  }
  EXPECT_EQ(hits, rays);  // every ray aims inside the sphere
  EXPECT_GE(agree, hits * 99 / 100);
  EXPECT_GE(onSphere, hits * 99 / 100);
}

TEST(ViewerStreaming, aTinyBudgetIsKeptAndConvergesToThePictureOfAnUnlimitedOne) {
  const uint32_t w = 96, h = 96;
  const auto asset = Asset::open(files().chunked);
  ASSERT_GT(asset->reader.chunks().size(), 20u);
  Scene scene = sceneFor(*asset);
  // A close view of part of the torus: it needs some chunks, not all.
  Camera& c = *scene.camera;
  for (int k = 0; k < 3; ++k) c.eye[k] = c.target[k] + 0.25 * (c.eye[k] - c.target[k]);
  const GpuRun unlimited = renderGpu(*asset, scene, w, h, uint64_t(1) << 30);
  ASSERT_TRUE(unlimited.converged);
  const uint64_t fixed = unlimited.peak - unlimited.stats.poolBytes;
  const uint64_t needed = unlimited.stats.poolBytesInUse;
  const uint32_t resident = unlimited.stats.resident;
  std::printf("unlimited: %u of %zu chunks, pool %llu of %llu bytes in use, GPU memory %llu\n",
              resident, asset->reader.chunks().size(), (unsigned long long)needed,
              (unsigned long long)unlimited.stats.poolBytes, (unsigned long long)unlimited.peak);
  ASSERT_LT(resident, asset->reader.chunks().size()) << "the view should not need every chunk";
  // A budget with room for what the view needs and two pages more (besides a page a pool buffer
  // that the renderer keeps for alignment), not for the whole file.
  const uint64_t vram = fixed + needed + (2 + gpu::kPoolBuffers) * 32768;
  ASSERT_LT(vram, unlimited.peak);
  const GpuRun tiny = renderGpu(*asset, scene, w, h, vram);
  EXPECT_LE(tiny.peak, vram);
  EXPECT_TRUE(tiny.converged);
  EXPECT_GT(tiny.frameCount, 2u);  // it took frames: the first ones show coarser levels
  EXPECT_GT(differing(tiny.first, tiny.pixels), 0.01);
  EXPECT_EQ(differing(tiny.pixels, unlimited.pixels, 0), 0.0);
  // Orbiting with that budget evicts chunks and stays inside it.
  Scene moved = scene;
  Camera& m = *moved.camera;
  for (int k = 0; k < 3; ++k) m.eye[k] = 2 * m.target[k] - m.eye[k];
  const GpuRun other = renderGpu(*asset, moved, w, h, vram);
  EXPECT_LE(other.peak, vram);
}

// A close view of part of the chunked torus: it needs some chunks, not all.
Scene closeView(const Asset& asset) {
  Scene scene = sceneFor(asset);
  Camera& c = *scene.camera;
  for (int k = 0; k < 3; ++k) c.eye[k] = c.target[k] + 0.25 * (c.eye[k] - c.target[k]);
  return scene;
}

TEST(ViewerStreaming,
     anOrbitWithFramesInFlightUnderATinyBudgetConvergesToThePictureOfAnUnlimitedOne) {
  const uint32_t w = 96, h = 96, views = 12;
  const auto asset = Asset::open(files().chunked);
  const Scene start = closeView(*asset);
  const auto header = asset->reader.header();
  const auto orbitView = [&](uint32_t f) {
    Scene s = start;
    const Camera& c = *start.camera;
    s.camera->eye = c.target + rotated(c.eye - c.target, normalized(c.up), 2 * M_PI * f / views);
    return s;
  };
  const Scene end = orbitView(views / 2);  // half way round
  for (uint32_t inFlight : {2u, 3u}) {
    SCOPED_TRACE(inFlight);
    const GpuRun unlimited =
        renderGpu(*asset, end, w, h, uint64_t(1) << 30, nullptr, 200, inFlight);
    ASSERT_TRUE(unlimited.converged);
    ASSERT_LT(unlimited.stats.resident, asset->reader.chunks().size());
    // Room for what one view needs and two pages more (and a page a pool buffer for alignment).
    const uint64_t vram = unlimited.peak - unlimited.stats.poolBytes +
                          unlimited.stats.poolBytesInUse + (2 + gpu::kPoolBuffers) * 32768;
    Gpu& g = gpu();
    const uint64_t before = g.memoryInUse;
    g.memoryPeak = before;
    GpuRun tiny;
    uint32_t evicted = 0, maxInFlight = 0;
    {
      Renderer renderer(g, *asset, nullptr, rendererOptions(w, h, vram, inFlight));
      renderer.onCollected([&](const FrameStats& s) { evicted += s.evicted; });
      // Around the torus without waiting for any frame: every view brings chunks in and evicts.
      for (uint32_t f = 0; f <= views / 2; f += 1) {
        for (int repeat = 0; repeat < 3; ++repeat) {
          const Scene view = orbitView(f);
          renderFrame(renderer, frameParams(view, header.frame, header.maxLevel, renderer.setup()));
          maxInFlight = std::max(maxInFlight, renderer.inFlight());
        }
      }
      renderUntilConverged(renderer, *asset, end, 200, tiny);
    }
    tiny.peak = g.memoryPeak - before;
    EXPECT_EQ(g.validationErrors->load(), 0u) << "Vulkan validation errors";
    EXPECT_EQ(maxInFlight, inFlight);
    EXPECT_GT(evicted, 0u) << "the orbit should not fit the budget";
    EXPECT_LE(tiny.peak, vram);
    EXPECT_TRUE(tiny.converged);
    EXPECT_EQ(differing(tiny.pixels, unlimited.pixels, 0), 0.0);
  }
}

std::vector<uint32_t> decodeAndBuild(const Asset& asset, uint32_t chunk) {
  return buildBlob(decodeSurfaceChunk(asset.reader, chunk), chunk, asset.tree, asset.blob);
}

// Wait until the loader has decoded what was asked of it.
void waitForLoader(const ChunkCache& cache) {
  for (int i = 0; i < 2000 && !cache.idle(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(cache.idle());
}

std::vector<uint32_t> pagesOf(const std::vector<ChunkCache::Upload>& uploads, uint32_t chunk) {
  std::vector<uint32_t> pages;
  for (const auto& up : uploads)
    if (up.chunk == chunk)
      for (uint32_t p = 0; p < blobPages(up.words.size()); ++p) pages.push_back(up.firstPage + p);
  return pages;
}

TEST(ViewerStreaming, pagesOfAnEvictedChunkAreNotReusedBeforeTheFramesThatMayReadThemComplete) {
  const auto asset = Asset::open(files().chunked);
  const auto chunks = asset->reader.chunks();
  const uint32_t top = asset->tree.topChunk();
  // The two largest chunks besides the top one, a and b; a pool with room for the top and a.
  std::vector<std::pair<uint32_t, uint32_t>> bySize;  // (pages, chunk)
  for (uint32_t c = 0; c < chunks.size(); ++c)
    if (c != top && chunks[c].kind == kSurfaceKind)
      bySize.push_back({blobPages(decodeAndBuild(*asset, c).size()), c});
  std::sort(bySize.rbegin(), bySize.rend());
  ASSERT_GE(bySize.size(), 2u);
  const uint32_t a = bySize[0].second, b = bySize[1].second;
  const uint32_t topPages = blobPages(decodeAndBuild(*asset, top).size());
  for (const bool deferred : {true, false}) {
    SCOPED_TRACE(deferred ? "frames in flight" : "one frame at a time");
    ChunkCache cache(asset->reader, asset->tree, asset->blob, topPages + bySize[0].first,
                     topPages + bySize[0].first);
    std::vector<uint32_t> evicted;
    cache.gpuProgress(0, 0);
    ASSERT_EQ(cache.place(0, 1 << 30, evicted).size(), 1u);  // frame 1: the top chunk
    cache.request(a, 1);                                     // frame 1's rays ask for a
    waitForLoader(cache);
    cache.gpuProgress(1, 1);
    const auto placedA = cache.place(1, 1 << 30, evicted);  // frame 2 draws a
    const std::vector<uint32_t> pagesA = pagesOf(placedA, a);
    ASSERT_EQ(pagesA.size(), bySize[0].first);
    cache.request(b, 2);  // frame 2's rays ask for b and no ray uses a
    waitForLoader(cache);
    // Frame 4 is prepared while frame 3 is in flight (or, one at a time, after it completed):
    // placing b evicts a, whose pages frames 2 and 3 were told about.
    cache.gpuProgress(3, deferred ? 2 : 3);
    const auto atFrame4 = cache.place(2, 1 << 30, evicted);
    EXPECT_EQ(evicted, std::vector<uint32_t>{a});
    EXPECT_FALSE(cache.resident(a));
    if (!deferred) {  // nothing in flight: a's pages are b's at once
      EXPECT_EQ(cache.retiredPages(), 0u);
      ASSERT_EQ(pagesOf(atFrame4, b).size(), bySize[1].first);
      continue;
    }
    EXPECT_TRUE(atFrame4.empty()) << "b was placed on pages frame 3 may still read";
    EXPECT_EQ(cache.retiredPages(), pagesA.size());
    cache.gpuProgress(4, 2);  // frame 5: frame 3 still in flight
    EXPECT_TRUE(cache.place(2, 1 << 30, evicted).empty());
    EXPECT_FALSE(cache.resident(b));
    cache.gpuProgress(5, 3);  // frame 6: frame 3 completed
    const std::vector<uint32_t> pagesB = pagesOf(cache.place(3, 1 << 30, evicted), b);
    ASSERT_EQ(pagesB.size(), bySize[1].first);
    EXPECT_EQ(cache.retiredPages(), 0u);
    for (uint32_t p : pagesB)  // the only free pages were a's
      EXPECT_NE(std::find(pagesA.begin(), pagesA.end(), p), pagesA.end());
    EXPECT_EQ(evicted.size(), 1u);  // and nothing else was evicted meanwhile
  }
}

TEST(ViewerScene, sceneFilesSetEverythingAndNameWhatTheyCannotUse) {
  TempDir dir;
  const auto file = dir / "scene.json";
  std::ofstream(file) << R"({"camera": {"eye": [0, 0, 5], "target": [0, 0, 0], "fov": 30},
    "lights": [{"type": "area", "position": [1, 2, 3], "u": [1, 0, 0], "v": [0, 1, 0],
                "samples": 4, "color": [1, 0.5, 0.25], "intensity": 2}],
    "material": {"color": [0.2, 0.3, 0.4], "reflectivity": 0.25, "transparency": 0.5,
                 "ior": 1.33}, "shadows": false, "bounces": 2, "samples": 4})";
  Scene scene;
  loadScene(file, scene);
  ASSERT_TRUE(scene.camera);
  EXPECT_EQ(scene.camera->fovDegrees, 30);
  ASSERT_EQ(scene.lights.size(), 1u);
  EXPECT_TRUE(scene.lights[0].area);
  EXPECT_EQ(scene.lights[0].samples, 4);
  EXPECT_FLOAT_EQ(scene.material.ior, 1.33f);
  EXPECT_FALSE(scene.shadows);
  EXPECT_EQ(scene.samples, 4);
  const auto fails = [&](const std::string& text, const std::string& expected) {
    std::ofstream(file) << text;
    Scene s;
    try {
      loadScene(file, s);
      ADD_FAILURE() << "accepted " << text;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  };
  fails(R"({"camera": {"eye": [0, 0, 5]}})", "camera");
  fails(R"({"lights": [{"type": "spot", "position": [0, 0, 0]}]})", "lights[].type");
  fails(R"({"material": {"reflectivity": 0.8, "transparency": 0.5}})", "material");
  fails(R"({"brightness": 2})", "'brightness': unknown key");
  fails(R"({"samples": 0.5})", "samples");
  fails("{not json", "not valid JSON");
  fails(R"({"draw": "splats"})", "draw");
  fails(R"({"ground": "low"})", "ground");
  fails(R"({"caustics": 1.5})", "caustics");
  fails(R"({"caustics": -3})", "caustics");
  std::ofstream(file) << R"({"draw": "both", "ground": -1.5, "ground_color": [0.1, 0.2, 0.3]})";
  Scene drawn;
  loadScene(file, drawn);
  EXPECT_EQ(drawn.draw, Draw::Both);
  EXPECT_EQ(drawn.groundHeight, -1.5);
  EXPECT_FLOAT_EQ(drawn.groundColor[2], 0.3f);
  // Image-space points: layers, the layer gap d̃, opacity one an input, shadow samples.
  std::ofstream(file) << R"({"image": {"layers": 3, "layer_gap": 0.02, "opacity": [1, 0.4],
    "shadow_samples": 10, "eye_dome": true}})";
  Scene image;
  loadScene(file, image);
  EXPECT_EQ(image.image.layers, 3);
  EXPECT_DOUBLE_EQ(image.image.layerGap, 0.02);
  EXPECT_EQ(image.image.opacity, (std::vector<float>{1.0f, 0.4f}));
  EXPECT_EQ(image.image.shadowSamples, 10);
  EXPECT_TRUE(image.image.eyeDome);
  fails(R"({"image": {"layers": 0}})", "image.layers");
  fails(R"({"image": {"layer_gap": -1}})", "image.layer_gap");
  fails(R"({"image": {"opacity": [1, 1.5]}})", "image.opacity");
  fails(R"({"image": {"shadow_samples": 2.5}})", "image.shadow_samples");
  fails(R"({"image": {"peel": 2}})", "'image.peel': unknown key");
  EXPECT_THROW(parseLight("spot:1,2,3"), std::invalid_argument);
  EXPECT_THROW(parseLight("point:1,2"), std::invalid_argument);
  const LightSpec l = parseLight("area:1,2,3:1,0,0:0,1,0:9:1,1,1:3");
  EXPECT_TRUE(l.area);
  EXPECT_EQ(l.samples, 9);
  EXPECT_FLOAT_EQ(l.intensity, 3.0f);
}


// Camera rays through the centers of the pixels of the scene's view (frame units).
std::vector<CpuRay> cameraRays(const Asset& asset, const Scene& scene, uint32_t w, uint32_t h) {
  const auto header = asset.reader.header();
  const gpu::FrameParams p =
      frameParams(scene, header.frame, header.maxLevel, cpuFrameSetup(asset, w, h, nullptr));
  std::vector<CpuRay> rays;
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      const float sx = 2.0f * (float(x) + 0.5f) / float(w) - 1.0f;
      const float sy = 1.0f - 2.0f * (float(y) + 0.5f) / float(h);
      const glm::vec3 d = glm::normalize(glm::vec3(p.forward) + sx * glm::vec3(p.right) +
                                         sy * glm::vec3(p.up));
      rays.push_back({glm::vec3(p.eye), d});
    }
  return rays;
}

// The splats' picture against the surface's, ray by ray: the intersection over the union of the
// pixels each covers (silhouettes), and the share of the pixels both cover where their depths
// differ by at most `tolerance` (frame units).
struct SplatAgreement {
  double iou = 0, within = 0;
  size_t surface = 0, splats = 0;
};

SplatAgreement splatAgreement(const CpuPool& pool, const std::vector<CpuRay>& rays,
                              double tolerance) {
  std::vector<std::optional<CpuHit>> surface(rays.size()), splats(rays.size());
  traceCpu(pool, finestFrameParams(pool), rays, surface);
  traceCpu(pool, splatFrameParams(pool, false), rays, splats);
  SplatAgreement a;
  size_t both = 0, either = 0, near = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    a.surface += surface[i].has_value();
    a.splats += splats[i].has_value();
    either += surface[i] || splats[i];
    if (!surface[i] || !splats[i]) continue;
    ++both;
    near += std::abs(surface[i]->t - splats[i]->t) <= tolerance;
  }
  if (std::getenv("ISO_SPLAT_DEBUG")) {
    std::vector<double> d;
    for (size_t i = 0; i < rays.size(); ++i)
      if (surface[i] && splats[i]) d.push_back((splats[i]->t - surface[i]->t) / tolerance * 2);
    std::sort(d.begin(), d.end());
    if (const char* out = std::getenv("ISO_SPLAT_MASK")) {
      const size_t w = size_t(std::sqrt(double(rays.size())));
      static int masks = 0;
      FILE* f = std::fopen((std::string(out) + std::to_string(masks++) + ".pgm").c_str(), "wb");
      std::fprintf(f, "P5 %zu %zu 255\n", w, rays.size() / w);
      for (size_t i = 0; i < rays.size(); ++i) {
        uint8_t v = surface[i] ? 80 : 0;
        if (splats[i]) v += 60;
        if (surface[i] && splats[i] && std::abs(surface[i]->t - splats[i]->t) > tolerance) v = 255;
        std::fputc(v, f);
      }
      std::fclose(f);
    }
    if (!d.empty())
      std::printf("  splat - surface depth, spacings: p5 %.2f p25 %.2f median %.2f p75 %.2f p95 %.2f\n",
                  d[d.size() / 20], d[d.size() / 4], d[d.size() / 2], d[3 * d.size() / 4],
                  d[19 * d.size() / 20]);
  }
  a.iou = either > 0 ? double(both) / double(either) : 0.0;
  a.within = both > 0 ? double(near) / double(both) : 0.0;
  return a;
}

// A view of the scene turned by `degrees` about the up axis through its target.
Scene orbited(const Scene& scene, double degrees) {
  Scene s = scene;
  Camera& c = *s.camera;
  c.eye = c.target + rotated(c.eye - c.target, normalized(c.up), degrees * M_PI / 180.0);
  return s;
}

TEST(ViewerGround, theGroundIsThePlaneItSaysDiffuseShadowedAndDrawnAlikeOnTheGpu) {
  const auto asset = Asset::open(files().sphere);
  Scene scene = sceneFor(*asset);
  scene.up = Vec3d(0, 1, 0);
  const double height = asset->bounds.lo[1] - 0.1 * (asset->bounds.hi[1] - asset->bounds.lo[1]);
  scene.groundHeight = height;
  const auto header = asset->reader.header();
  const uint32_t w = 128, h = 96;
  const gpu::FrameParams params =
      frameParams(scene, header.frame, header.maxLevel, cpuFrameSetup(*asset, w, h, nullptr));
  ASSERT_NE(params.options.x & gpu::kOptionGround, 0u);
  // Rays down onto the plane away from the sphere meet it where the plane is.
  const CpuPool pool = buildCpuPool(asset->reader);
  gpu::FrameParams rays = finestFrameParams(pool);
  rays.options.x |= gpu::kOptionGround;
  rays.ground = params.ground;
  const double size = header.frame.size;
  for (const glm::vec3 start : {glm::vec3(0.02f, 0.9f, 0.05f), glm::vec3(0.97f, 0.8f, 0.5f)}) {
    const glm::vec3 down = glm::normalize(glm::vec3(0.1f, -1.0f, 0.2f));
    const auto hit = traceCpu(pool, rays, start, down);
    ASSERT_TRUE(hit.has_value());
    const double y = header.frame.origin[1] + size * (start.y + hit->t * down.y);
    EXPECT_NEAR(y, height, 1e-5 * size);
    EXPECT_EQ(hit->normal, glm::vec3(0, 1, 0));
  }
  // Looking up from under the plane, away from the sphere: nothing (it is seen from above only).
  EXPECT_FALSE(traceCpu(pool, rays, glm::vec3(0.02f, -5.0f, 0.05f), glm::vec3(0, 1, 0)));
  // Drawn alike on the GPU; the sphere's shadow darkens the ground; a mirror material leaves the
  // ground as it was (it is diffuse).
  const auto cpuPicture = renderReference(*asset, scene, w, h);
  const GpuRun gpuPicture = renderGpu(*asset, scene, w, h, uint64_t(1) << 30);
  EXPECT_LE(differing(gpuPicture.pixels, cpuPicture), 0.005);
  Scene none = scene;
  none.groundHeight.reset();
  EXPECT_GT(differing(renderReference(*asset, none, w, h), cpuPicture), 0.2);
  Scene mirror = scene;
  mirror.material.reflectivity = 0.6f;
  const auto mirrored = renderReference(*asset, mirror, w, h);
  size_t groundSame = 0, ground = 0;
  const std::vector<CpuRay> cameraRaysOf = cameraRays(*asset, scene, w, h);
  std::vector<std::optional<CpuHit>> hits(cameraRaysOf.size());
  traceCpu(pool, params, cameraRaysOf, hits);
  size_t dark = 0, lit = 0;
  for (size_t i = 0; i < hits.size(); ++i) {
    if (!hits[i] || hits[i]->normal != glm::vec3(0, 1, 0)) continue;
    ++ground;
    groundSame += mirrored[i] == cpuPicture[i];
    const int g = int(cpuPicture[i] >> 8 & 0xFF);
    dark += g < 90;
    lit += g > 110;
  }
  EXPECT_GT(ground, w * h / 10);
  EXPECT_EQ(groundSame, ground);
  EXPECT_GT(dark, ground / 50);  // the shadow
  EXPECT_GT(lit, ground / 2);
}

// A glass ball (the generated sphere, radius 1 at the origin, n = 1.5) over the ground, lit by a point light straight
// above it, 20 radii from its center; the camera looks under the ball, 35 degrees down, at the
// point below its center. The ground is `below` radii under the center, or (0) where the light
// focuses: a ball lens's focal length is f = nR / (2 (n - 1)) from its center, and the light, s
// away, is imaged at v = f s / (s - f) past it.
struct Lens {
  Scene scene;
  Vec3d center;
  double radius = 0, focus = 0;  // world units
  Vec3d under() const { return {center.x, *scene.groundHeight, center.z}; }
};

Lens lensScene(double below = 0) {
  Lens l;
  const ShapeParams sphere;  // the generated sphere's
  l.center = sphere.center;
  l.radius = sphere.radius;
  const double n = 1.5, s = 20 * l.radius, f = n * l.radius / (2 * (n - 1));
  l.focus = f * s / (s - f);
  Scene& scene = l.scene;
  scene.up = Vec3d(0, 1, 0);
  scene.groundHeight = l.center.y - (below > 0 ? below * l.radius : l.focus);
  scene.camera = Camera{l.under() + Vec3d(0, 3.5 * l.radius, 5 * l.radius), l.under(),
                        Vec3d(0, 1, 0), 40.0};
  LightSpec light;
  light.position = l.center + Vec3d(0, s, 0);
  scene.lights = {light};
  scene.material.transparency = 1.0f;
  scene.material.ior = float(n);
  scene.caustics = 300000;
  return l;
}

// The caustic map's irradiance (light colors) summed over its cells within `within` (world
// units) of a point, times the cells' area (frame units²): the flux landing there; or over all
// cells.
double causticFlux(const CausticMap& map, const gpu::FrameParams& p, const Frame& frame,
                   const Vec3d& at, double within = 1e300) {
  const glm::dvec3 u(p.causticU), v(p.causticV);
  const glm::dvec3 q = (at - glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2])) /
                       frame.size;
  const double x = glm::dot(u, q) + p.causticU.w, y = glm::dot(v, q) + p.causticV.w;
  const double cells = within / frame.size * glm::length(u), cellArea = 1.0 / glm::dot(u, u);
  double sum = 0;
  for (uint32_t j = 0; j < gpu::kCausticCells; ++j)
    for (uint32_t i = 0; i < gpu::kCausticCells; ++i) {
      if (std::hypot(i + 0.5 - x, j + 0.5 - y) > cells) continue;
      const size_t at3 = 3 * (size_t(j) * gpu::kCausticCells + i);
      sum += map.words[at3 + 1];  // green (the light is white)
    }
  return sum / gpu::kCausticScale * cellArea;
}

// The same flux from the exact ball: rays from the light through a grid over the caustic disc,
// each carrying its share of the light as a photon does, refracted into and out of the sphere
// (center and radius of the Lens, frame units) by Snell's law, summed where they land on the
// ground into the map's cells, then over the cells within each of `within` (world units) of the
// point under the center. The brute-force reference of the photon map.
std::vector<double> exactLensFlux(const Lens& lens, const gpu::FrameParams& p, const Frame& frame,
                                  const std::vector<double>& within) {
  const glm::dvec3 origin(frame.origin[0], frame.origin[1], frame.origin[2]);
  const auto toFrame = [&](const Vec3d& w) { return (w - origin) / frame.size; };
  const glm::dvec3 c = toFrame(lens.center), light = toFrame(lens.scene.lights[0].position);
  const double r = lens.radius / frame.size, groundY = toFrame(lens.under()).y;
  const glm::dvec3 discCenter(p.causticDisc), u(p.causticU), v(p.causticV);
  const double disc = p.causticDisc.w;
  const glm::dvec3 axis = glm::normalize(discCenter - light);
  const glm::dvec3 e1 = glm::normalize(glm::cross(axis, glm::dvec3(1, 0, 0))),
                   e2 = glm::cross(axis, e1);
  const glm::dvec3 under = toFrame(lens.under());
  const double ux = glm::dot(u, under) + p.causticU.w, uy = glm::dot(v, under) + p.causticV.w;
  const double cellsPerWorld = glm::length(u) / frame.size;
  const double n = lens.scene.material.ior;
  std::vector<double> sums(within.size(), 0.0);
  constexpr int kGrid = 1500;
  const double step = 2.0 * disc / kGrid;
  // The first hit of a ray on the sphere from outside (or, inside, its exit): t, or none.
  const auto sphereHit = [&](const glm::dvec3& o, const glm::dvec3& d, bool inside) {
    const glm::dvec3 oc = o - c;
    const double b = glm::dot(oc, d), q = glm::dot(oc, oc) - r * r, h = b * b - q;
    if (h < 0) return -1.0;
    return inside ? -b + std::sqrt(h) : -b - std::sqrt(h);
  };
  for (int j = 0; j < kGrid; ++j)
    for (int i = 0; i < kGrid; ++i) {
      const double a = -disc + (i + 0.5) * step, b = -disc + (j + 0.5) * step;
      if (a * a + b * b > disc * disc) continue;
      glm::dvec3 d = glm::normalize(discCenter + a * e1 + b * e2 - light);
      const double flux = step * step * glm::dot(d, axis);
      const double t0 = sphereHit(light, d, false);
      if (t0 < 0) continue;
      glm::dvec3 at = light + t0 * d;
      d = glm::refract(d, glm::normalize(at - c), 1.0 / n);
      at += sphereHit(at, d, true) * d;
      const glm::dvec3 out = glm::normalize(at - c);
      d = glm::refract(d, -out, n);
      if (glm::dot(d, d) == 0 || d.y >= 0) continue;
      const glm::dvec3 land = at + (groundY - at.y) / d.y * d;
      const double x = glm::dot(u, land) + p.causticU.w, y = glm::dot(v, land) + p.causticV.w;
      if (!(x >= 0 && y >= 0 && x < gpu::kCausticCells && y < gpu::kCausticCells)) continue;
      const double off = std::hypot(std::floor(x) + 0.5 - ux, std::floor(y) + 0.5 - uy);
      for (size_t k = 0; k < within.size(); ++k)
        if (off <= within[k] * cellsPerWorld) sums[k] += flux;
    }
  return sums;
}

TEST(ViewerCaustics, aGlassBallFocusesTheLightThatEntersItAsTheExactBallDoes) {
  const auto asset = Asset::open(files().sphere);
  const auto header = asset->reader.header();
  const CpuPool pool = buildCpuPool(asset->reader);
  const auto paramsOf = [&](const Scene& scene) {
    return frameParams(scene, header.frame, header.maxLevel,
                       cpuFrameSetup(*asset, 96, 96, nullptr));
  };
  // The ground just under the ball, where the lens formula puts the (paraxial) focus, and far
  // past it.
  for (const double below : {1.1, 0.0, 3.0}) {
    const Lens lens = lensScene(below);
    const gpu::FrameParams params = paramsOf(lens.scene);
    ASSERT_EQ(params.caustics.y, lens.scene.caustics);
    const CausticMap map = causticMapCpu(pool, params);
    EXPECT_EQ(map.photons, lens.scene.caustics);
    const double rad = lens.radius;
    const std::vector<double> within = {0.1 * rad, 0.25 * rad, 0.5 * rad, 1e300};
    const std::vector<double> exact = exactLensFlux(lens, params, header.frame, within);
    std::printf("ground %.3f radii under the center (%.2f Mphotons/s):", 
                (lens.center.y - *lens.scene.groundHeight) / rad, map.photons / map.seconds / 1e6);
    for (size_t k = 0; k < within.size(); ++k) {
      const double got = causticFlux(map, params, header.frame, lens.under(), within[k]);
      std::printf(" [%.2g radii: %.5f exact %.5f]", within[k] / rad, got, exact[k]);
      EXPECT_NEAR(got, exact[k], 0.02 * exact[k] + 0.001) << within[k] / rad << " radii";
    }
    std::printf("\n");
  }
}

TEST(ViewerCaustics, theCausticBrightensTheFocusLeavesTheRestAsItWasAndIsDrawnAlikeOnTheGpu) {
  const auto asset = Asset::open(files().sphere);
  const auto header = asset->reader.header();
  const Lens lens = lensScene();
  const uint32_t w = 128, h = 96;
  const auto caustic = renderReference(*asset, lens.scene, w, h);
  Scene plain = lens.scene;
  plain.caustics = 0;
  const auto without = renderReference(*asset, plain, w, h);
  // Where each pixel's camera ray meets the ground (world units).
  const CpuPool pool = buildCpuPool(asset->reader);
  const std::vector<CpuRay> rays = cameraRays(*asset, lens.scene, w, h);
  std::vector<std::optional<CpuHit>> hits(rays.size());
  traceCpu(pool, frameParams(lens.scene, header.frame, header.maxLevel,
                             cpuFrameSetup(*asset, w, h, nullptr)),
           rays, hits);
  size_t focus = 0, brighter = 0, far = 0, same = 0;
  int farDiff = 0;
  for (size_t i = 0; i < hits.size(); ++i) {
    if (!hits[i] || hits[i]->normal != glm::vec3(0, 1, 0)) continue;
    const glm::dvec3 q = glm::dvec3(rays[i].origin) + double(hits[i]->t) * glm::dvec3(rays[i].direction);
    const Vec3d p = glm::dvec3(header.frame.origin[0], header.frame.origin[1],
                               header.frame.origin[2]) + q * header.frame.size;
    const double off = std::hypot(p.x - lens.center.x, p.z - lens.center.z) / lens.radius;
    const int green = int(caustic[i] >> 8 & 0xFF), greenWithout = int(without[i] >> 8 & 0xFF);
    if (off < 0.1) {
      ++focus;
      brighter += green > greenWithout + 40;
    } else if (off > 4.0) {
      ++far;
      same += caustic[i] == without[i];
      farDiff = std::max(farDiff, green - greenWithout);
    }
  }
  std::printf("ground pixels: %zu in the focus, %zu of them brighter; %zu far, %zu the same "
              "(at most %d/255 brighter)\n", focus, brighter, far, same, farDiff);
  EXPECT_GT(focus, 4u);
  EXPECT_EQ(brighter, focus);
  // Far from the focus the picture is the same, but for the faint light of rays that graze the
  // ball (they leave it at up to 96 degrees from their way in, and land anywhere).
  EXPECT_GT(far, w * h / 20);
  EXPECT_GE(double(same), 0.97 * double(far));
  EXPECT_LE(farDiff, 4);  // measured: 4/255 with the corner fit (its default), 2 without
  const GpuRun gpuPicture = renderGpu(*asset, lens.scene, w, h, uint64_t(1) << 30);
  const double gpuDiffers = differing(gpuPicture.pixels, caustic, 8);
  const double causticDiffers = differing(caustic, without, 8);
  std::printf("pixels over 8/255 apart: GPU and CPU %.4f %%, with and without caustics %.4f %%\n",
              100 * gpuDiffers, 100 * causticDiffers);
  EXPECT_LE(gpuDiffers, 0.005);
  EXPECT_GT(causticDiffers, 0.01);
}

TEST(ViewerCaustics, streamedChunksGiveTheCausticsOfTheWholeFile) {
  // A glass torus in many chunks that stream in a few a frame: its photons ask for the chunks
  // they meet, and the map is made again as they arrive, to the CPU reference's (all resident).
  const auto asset = Asset::open(files().chunked);
  ASSERT_GT(asset->reader.chunks().size(), 10u);
  Scene scene = sceneFor(*asset);
  scene.up = Vec3d(0, 1, 0);
  scene.groundHeight = asset->bounds.lo.y - 0.2 * (asset->bounds.hi.y - asset->bounds.lo.y);
  scene.material.transparency = 0.9f;
  scene.caustics = 200000;
  const uint32_t w = 128, h = 96;
  const auto cpuPicture = renderReference(*asset, scene, w, h);
  const GpuRun streamed = renderGpu(*asset, scene, w, h, uint64_t(1) << 30);
  EXPECT_TRUE(streamed.converged);
  EXPECT_GT(streamed.frameCount, 2u);
  const double differs = differing(streamed.pixels, cpuPicture);
  Scene plain = scene;
  plain.caustics = 0;
  const double caustic = differing(renderReference(*asset, plain, w, h), cpuPicture);
  std::printf("streamed in %u frames: %.4f %% of the pixels over 8/255 from the CPU's; the "
              "caustics change %.4f %%\n", streamed.frameCount, 100 * differs, 100 * caustic);
  EXPECT_LE(differs, 0.005);
  EXPECT_GT(caustic, 0.01);
}

TEST(ViewerCaustics, theGpuRecomputesTheMapWhenTheLightTheMaterialOrTheGroundChangesOnly) {
  const auto asset = Asset::open(files().sphere);
  const auto header = asset->reader.header();
  const Lens lens = lensScene();
  RendererOptions o = rendererOptions(64, 48, uint64_t(1) << 30, 2);
  o.caustics = true;
  Renderer renderer(gpu(), *asset, nullptr, o);
  // The photons each frame traced (the renderer's feedback).
  const auto photons = [&](const Scene& scene) {
    renderFrame(renderer, frameParams(scene, header.frame, header.maxLevel, renderer.setup()));
    renderer.finish();
    return renderer.stats().photons;
  };
  const uint64_t all = lens.scene.caustics;
  EXPECT_EQ(photons(lens.scene), all);
  EXPECT_EQ(photons(lens.scene), 0u);
  Scene moved = lens.scene;  // the camera alone moved
  moved.camera->eye += Vec3d(0.5, 0.2, 0);
  EXPECT_EQ(photons(moved), 0u);
  Scene lit = moved;
  lit.lights[0].position += Vec3d(1, 0, 0);
  EXPECT_EQ(photons(lit), all);
  Scene glass = lit;
  glass.material.ior = 1.33f;
  EXPECT_EQ(photons(glass), all);
  EXPECT_EQ(photons(glass), 0u);
  Scene lower = glass;
  *lower.groundHeight -= 0.5;
  EXPECT_EQ(photons(lower), all);
  Scene off = lower;
  off.caustics = 0;
  EXPECT_EQ(photons(off), 0u);
  EXPECT_EQ(photons(lower), all);
  EXPECT_EQ(gpu().validationErrors->load(), 0u);
}

TEST(ViewerSplats, aSpheresSplatsHaveTheSurfacesSilhouetteAndDepth) {
  // Issue targets: silhouette IoU >= 0.97; depths within 2 spacings on >= 98 % of the pixels.
  const auto asset = Asset::open(files().spherePoints);
  ASSERT_TRUE(asset->splats.has_value());
  const CpuPool pool = buildCpuPool(asset->reader, {}, true);
  const double spacing = files().spherePointsSpacing / asset->reader.header().frame.size;
  for (const double degrees : {0.0, 70.0, 190.0}) {
    const Scene scene = orbited(sceneFor(*asset), degrees);
    const SplatAgreement a = splatAgreement(pool, cameraRays(*asset, scene, 200, 200), 2 * spacing);
    std::printf("sphere at %.0f degrees: silhouette IoU %.4f, depth within 2 spacings %.4f "
                "(%zu and %zu pixels)\n",
                degrees, a.iou, a.within, a.surface, a.splats);
    EXPECT_GT(a.surface, 200u * 200u / 10);
    EXPECT_GE(a.iou, 0.97);
    EXPECT_GE(a.within, 0.98);
  }
}

TEST(ViewerSplats, aScansSplatsAndSurfaceAgreeInDepthFromEverySide) {
  // Issue target: depths within 2 spacings on >= 98 % of the pixels both cover, asserted on a
  // torus scanned with noise (0.3 spacings). The kitten (5,210 points) is held to 95 %: from one
  // side its thin ears differ (its surface is 0.25 spacings RMS from its points, 1.8 at most).
  for (const auto& [file, worldSpacing, least] :
       {std::tuple{files().noisyPoints, files().noisySpacing, 0.98},
        std::tuple{files().kittenPoints, files().kittenSpacing, 0.95}}) {
    SCOPED_TRACE(file.filename().string());
    const auto asset = Asset::open(file);
    const CpuPool pool = buildCpuPool(asset->reader, {}, true);
    const double spacing = worldSpacing / asset->reader.header().frame.size;
    for (const double degrees : {0.0, 90.0, 180.0, 270.0}) {
      const Scene scene = orbited(sceneFor(*asset), degrees);
      const SplatAgreement a =
          splatAgreement(pool, cameraRays(*asset, scene, 320, 320), 2 * spacing);
      std::printf("%s at %.0f degrees: silhouette IoU %.4f, depth within 2 spacings %.4f\n",
                  file.filename().c_str(), degrees, a.iou, a.within);
      EXPECT_GE(a.within, least);
      EXPECT_GE(a.iou, 0.9);
    }
  }
}

TEST(ViewerSplats, theGpuAndTheCpuReferenceDrawTheSameSplats) {
  const uint32_t w = 160, h = 120;
  for (const auto& file : {files().spherePoints, files().kittenPoints}) {
    for (const Draw draw : {Draw::Points, Draw::Both}) {
      SCOPED_TRACE(file.filename().string() + " " + std::string(nameOf(kDrawNames, draw)));
      const auto asset = Asset::open(file);
      Scene scene = sceneFor(*asset);
      scene.draw = draw;
      scene.material.reflectivity = 0.2f;  // shadows and reflections of splats, too
      const GpuRun gpuPicture = renderGpu(*asset, scene, w, h, uint64_t(1) << 30);
      const auto header = asset->reader.header();
      const CpuPool pool = buildCpuPool(asset->reader, {}, true);
      const auto cpuPicture =
          renderCpu(pool,
                    frameParams(scene, header.frame, header.maxLevel,
                                cpuFrameSetup(*asset, w, h, nullptr)),
                    nullptr)
              .pixels;
      EXPECT_TRUE(gpuPicture.converged);
      const double differ = differing(gpuPicture.pixels, cpuPicture);
      std::printf("%s, %s: %.4f %% of the pixels differ by more than 8/255\n",
                  file.filename().c_str(), std::string(nameOf(kDrawNames, draw)).c_str(),
                  100 * differ);
      EXPECT_LE(differ, 0.005);
      // The splats are drawn: the kitten's picture is not its surface's (the sphere's splats draw
      // its surface's picture within 8/255 on all but a few pixels).
      scene.draw = Draw::Surface;
      const double fromSurface = differing(renderReference(*asset, scene, w, h), cpuPicture);
      std::printf("  %.4f %% of the pixels differ from the surface's picture\n", 100 * fromSurface);
      if (file == files().kittenPoints) {
        EXPECT_GT(fromSurface, 0.01);
      }
    }
  }
}

TEST(ViewerSplats, fromAfarSubsamplesAreDrawnAndATinyBudgetConvergesToTheUnlimitedPicture) {
  const uint32_t w = 96, h = 96;
  const auto asset = Asset::open(files().chunkedPoints);
  ASSERT_TRUE(asset->splats.has_value());
  size_t points = 0, subsamples = 0;
  const std::vector<bool> subsample = subsampleChunks(asset->reader);
  for (const ChunkInfo& c : asset->reader.chunks())
    if (c.kind == kPointsKind) (subsample[c.id] ? subsamples : points) += 1;
  ASSERT_GT(points, 10u);
  ASSERT_GT(subsamples, 2u);
  Scene far = sceneFor(*asset);
  Camera& c = *far.camera;
  for (int k = 0; k < 3; ++k) c.eye[k] = c.target[k] + 3.0 * (c.eye[k] - c.target[k]);
  far.draw = Draw::Points;
  far.lodPixels = 4.0f;  // splats of up to 4 pixels: the subsamples stand in for their chunks
  const GpuRun coarse = renderGpu(*asset, far, w, h, uint64_t(1) << 30);
  ASSERT_TRUE(coarse.converged);
  Scene fine = far;
  fine.lodPixels = 0.0f;  // the finest chunks everywhere
  const GpuRun finest = renderGpu(*asset, fine, w, h, uint64_t(1) << 30);
  std::printf("splats from afar: %u chunks resident with subsamples, %u at the finest\n",
              coarse.stats.resident, finest.stats.resident);
  EXPECT_LT(coarse.stats.resident, finest.stats.resident);
  EXPECT_LE(differing(coarse.pixels, finest.pixels, 24), 0.05);
  // A close view under a budget that holds what it needs and little more.
  Scene close = closeView(*asset);
  close.draw = Draw::Points;
  const GpuRun unlimited = renderGpu(*asset, close, w, h, uint64_t(1) << 30);
  ASSERT_TRUE(unlimited.converged);
  const uint64_t fixed = unlimited.peak - unlimited.stats.poolBytes;
  const uint64_t vram = fixed + unlimited.stats.poolBytesInUse + (2 + gpu::kPoolBuffers) * 32768;
  ASSERT_LT(vram, unlimited.peak);
  const GpuRun tiny = renderGpu(*asset, close, w, h, vram);
  EXPECT_LE(tiny.peak, vram);
  EXPECT_TRUE(tiny.converged);
  EXPECT_EQ(differing(tiny.pixels, unlimited.pixels, 0), 0.0);
}

}  // namespace
}  // namespace iso::test
