// Image-space point rendering (tracer/point_image.h) against analytic answers and brute force:
// hole filling against a sphere's silhouette, occluded filling, depth peeling against per-pixel
// sorting, shadow textures against analytic shadows and penumbrae.
#include "tracer/point_image.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/glm.hpp>
#include <numbers>
#include <random>
#include <vector>

#include "iso/error.h"
#include "shaders/shared.h"
#include "point_scenes.h"

namespace iso::viewer {
namespace {

using glm::vec3;
constexpr uint32_t kNone = gpu::kImageNoPoint;

// The direction through the center of pixel (x, y) of this camera (as the renderer projects).
vec3 pixelRay(const ImageCamera& c, int x, int y) {
  const vec3 f = glm::normalize(c.target - c.eye);
  const vec3 r = glm::normalize(glm::cross(f, c.up));
  const vec3 u = glm::cross(r, f);
  const float t = std::tan(glm::radians(c.fovDegrees) * 0.5f);
  const float sx = ((float(x) + 0.5f) / float(c.width) * 2.0f - 1.0f) * t * float(c.width) / float(c.height);
  const float sy = (1.0f - (float(y) + 0.5f) / float(c.height) * 2.0f) * t;
  return glm::normalize(f + sx * r + sy * u);
}

float pixelAngle(const ImageCamera& c) {
  return 2.0f * std::tan(glm::radians(c.fovDegrees) * 0.5f) / float(c.height);
}

// The points of a sphere land 3 to 4 pixels apart: unfilled, most of its silhouette is
// background; filled, every pixel more than a pixel inside the analytic silhouette is covered
// and none more than a pixel outside it.
TEST(PointImage, FillsASparseSphereExactlyToItsSilhouette) {
  const float radius = 1.0f;
  ImageCamera camera;
  camera.eye = vec3(0.3f, 0.4f, 4.0f);
  camera.target = vec3(0.0f);
  camera.width = camera.height = 256;
  // Points 3.5 pixels apart at the sphere's front (distance about 3).
  const float spacing = 3.5f * pixelAngle(camera) * (glm::length(camera.eye) - radius);
  const size_t n = size_t(4.0f * std::numbers::pi_v<float> * radius * radius / (spacing * spacing));
  ImageObject ball = sphere(vec3(0.0f), radius, n);
  PointImageRenderer renderer({ball});
  ImageSettings settings;
  settings.antialias = ImageAntialias::Off;
  settings.maxFillPasses = 0;
  const ImageResult raw = renderer.render(camera, {}, settings);
  settings.maxFillPasses = 64;
  const ImageResult filled = renderer.render(camera, {}, settings);

  const float distance = glm::length(camera.eye);
  const float edge = std::asin(radius / distance);
  const float pixel = pixelAngle(camera) * 1.0f;
  size_t inside = 0, rawCovered = 0, holes = 0, spilled = 0;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const float angle = std::acos(std::clamp(
          glm::dot(pixelRay(camera, x, y), -glm::normalize(camera.eye)), -1.0f, 1.0f));
      const size_t k = size_t(y) * camera.width + x;
      if (angle < edge - pixel) {
        ++inside;
        rawCovered += raw.points[k] != kNone;
        holes += filled.points[k] == kNone;
      } else if (angle > edge + pixel) {
        spilled += filled.points[k] != kNone;
      }
    }
  ASSERT_GT(inside, 10000u);
  EXPECT_LT(double(rawCovered) / double(inside), 0.3) << "the sampling is not sparse";
  EXPECT_EQ(holes, 0u);
  EXPECT_EQ(spilled, 0u);
  EXPECT_GE(filled.stats.backgroundPasses.at(0), 2);
}

// A sparse front sheet (points 3.5 pixels apart) before a dense back sheet farther than d̃: the
// back sheet shows through the front one's gaps until occluded pixels are filled.
TEST(PointImage, FrontSheetCoversTheDenseSheetBehindIt) {
  ImageCamera camera;
  camera.eye = vec3(0.05f, -0.08f, 3.0f);
  camera.target = vec3(0.0f);
  camera.width = camera.height = 256;
  const float frontSpacing = 3.5f * pixelAngle(camera) * 3.0f;
  ImageObject front = sheet(vec3(0.0f), vec3(1, 0, 0), vec3(0, 1, 0), 0.5f, frontSpacing, 1);
  ImageObject back = sheet(vec3(0, 0, -0.5f), vec3(1, 0, 0), vec3(0, 1, 0), 1.2f,
                           0.7f * pixelAngle(camera) * 3.5f, 2);
  const size_t frontCount = front.positions.size();
  PointImageRenderer renderer({front, back});
  ImageSettings settings;
  settings.layerGap = 0.1f;
  settings.antialias = ImageAntialias::Off;
  const ImageResult result = renderer.render(camera, {}, settings);
  size_t inside = 0, showsFront = 0;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const vec3 d = pixelRay(camera, x, y);
      const vec3 hit = camera.eye + d * (-camera.eye.z / d.z);  // on the front sheet's plane
      const float margin = 1.5f * pixelAngle(camera) * 3.0f;
      if (std::abs(hit.x) > 0.5f - margin || std::abs(hit.y) > 0.5f - margin) continue;
      ++inside;
      const uint32_t point = result.points[size_t(y) * camera.width + x];
      showsFront += point != kNone && point < frontCount;
    }
  ASSERT_GT(inside, 5000u);
  std::printf("the front sheet shows on %.2f %% of its silhouette, after %d occluded passes\n",
              100.0 * double(showsFront) / double(inside), result.stats.occludedPasses.at(0));
  EXPECT_GE(double(showsFront) / double(inside), 0.99);
  EXPECT_GE(result.stats.occludedPasses.at(0), 1);
}

// Phong as the renderer defines it (shaders/image.h), written out again for the reference.
vec3 phong(vec3 p, vec3 n, vec3 color, const ImageCamera& camera, const ImageLight& light,
           const ImageSettings& s) {
  const vec3 toEye = glm::normalize(camera.eye - p);
  if (glm::dot(n, toEye) < 0.0f) n = -n;
  vec3 c = s.ambient * color;
  const vec3 toLight = glm::normalize(light.position - p);
  const float diffuse = glm::dot(n, toLight);
  if (diffuse > 0.0f) {
    const vec3 reflected = 2.0f * diffuse * n - toLight;
    const float specular = std::pow(std::max(glm::dot(reflected, toEye), 0.0f), s.shininess);
    c += light.color * (s.diffuse * diffuse * color + s.specular * specular);
  }
  return c;
}

// Three nested spheres of known opacities, peeled into layers and blended, against a reference
// that sorts every point of every pixel by depth, groups them into surfaces d̃ apart and blends
// the surfaces' nearest points front to back. Returns the RMSE of the colors.
double peelingError(bool cull, int layers, bool smooth) {
  ImageCamera camera;
  camera.eye = vec3(0.2f, 0.5f, 4.0f);
  camera.target = vec3(0.0f);
  camera.width = camera.height = 160;
  const float pixel = pixelAngle(camera) * 3.0f;
  std::vector<ImageObject> objects;
  const float radii[3] = {1.0f, 0.65f, 0.3f};
  const vec3 colors[3] = {{0.2f, 0.3f, 0.9f}, {0.2f, 0.8f, 0.3f}, {0.6f, 0.35f, 0.2f}};
  const float opacities[3] = {0.3f, 0.5f, 1.0f};
  for (int s = 0; s < 3; ++s) {
    // Dense: about 0.6 pixels apart, so that the reference sees each surface in every pixel.
    const float spacing = 0.6f * pixel;
    const size_t n = size_t(4.0f * std::numbers::pi_v<float> * radii[s] * radii[s] / (spacing * spacing));
    ImageObject o = sphere(vec3(0.0f), radii[s], n);
    o.color = colors[s];
    o.opacity = opacities[s];
    objects.push_back(std::move(o));
  }
  const ImageLight light{vec3(3.0f, 4.0f, 5.0f)};
  ImageSettings settings;
  settings.layers = layers;
  settings.cull = cull;
  settings.layerGap = 0.15f;
  settings.antialias = ImageAntialias::Off;
  settings.smooth = smooth;
  settings.background = vec3(1.0f);
  PointImageRenderer renderer(objects);
  const ImageResult result = renderer.render(camera, std::span(&light, 1), settings);
  EXPECT_EQ(result.stats.layers, layers);

  // The reference: every front-facing point into its pixel's list.
  struct Entry {
    float depth;
    vec3 color;
    float alpha;
  };
  std::vector<std::vector<Entry>> lists(size_t(camera.width) * camera.height);
  const vec3 f = glm::normalize(camera.target - camera.eye);
  for (int s = 0; s < 3; ++s)
    for (size_t i = 0; i < objects[s].positions.size(); ++i) {
      const vec3 p = objects[s].positions[i], n = objects[s].normals[i];
      const vec3 v = p - camera.eye;
      if (cull && glm::dot(n, v) > 0.0f) continue;  // faces away
      const vec3 r = glm::normalize(glm::cross(f, camera.up)), u = glm::cross(r, f);
      const float t = std::tan(glm::radians(camera.fovDegrees) * 0.5f);
      const float z = glm::dot(v, f);
      const float x = (glm::dot(v, r) / (z * t) * 0.5f + 0.5f) * float(camera.width);
      const float y = (0.5f - glm::dot(v, u) / (z * t) * 0.5f) * float(camera.height);
      if (x < 0 || y < 0 || x >= float(camera.width) || y >= float(camera.height)) continue;
      lists[size_t(int(y)) * camera.width + size_t(int(x))].push_back(
          {glm::length(v), phong(p, n, objects[s].color, camera, light, settings), opacities[s]});
    }
  double squared = 0.0;
  size_t compared = 0;
  for (size_t k = 0; k < lists.size(); ++k) {
    auto& list = lists[k];
    if (list.empty()) continue;
    std::sort(list.begin(), list.end(), [](const Entry& a, const Entry& b) { return a.depth < b.depth; });
    vec3 sum(0.0f);
    float alpha = 0.0f;
    float start = -1.0f;
    int layers = 0;
    for (const Entry& e : list) {
      if (start >= 0.0f && e.depth <= start + settings.layerGap) continue;  // the same surface
      start = e.depth;
      if (++layers > settings.layers) break;
      sum += (1.0f - alpha) * e.alpha * e.color;
      alpha += (1.0f - alpha) * e.alpha;
    }
    const vec3 expected = sum + (1.0f - alpha) * settings.background;
    const vec3 d = result.color[k] - expected;
    squared += glm::dot(d, d) / 3.0;
    ++compared;
  }
  EXPECT_GT(compared, 8000u);
  return std::sqrt(squared / double(compared));
}

// The front halves (culled back faces): three layers.
TEST(PointImage, PeeledLayersBlendAsPerPixelSorting) { EXPECT_LT(peelingError(true, 3, false), 0.02); }

// Front and back halves, six layers, smoothed as drawn by default (the paper's nested tori).
TEST(PointImage, SixPeeledLayersOfNestedSpheresBlendAsPerPixelSorting) {
  EXPECT_LT(peelingError(false, 6, true), 0.03);
}

// Whether the segment from p to the light crosses the sphere.
bool blocked(vec3 p, vec3 light, vec3 center, float radius) {
  const vec3 d = light - p;
  const float length = glm::length(d);
  const vec3 u = d / length;
  const float t = glm::dot(center - p, u);
  if (t < 0.0f || t > length) return false;
  const vec3 closest = p + t * u;
  return glm::dot(closest - center, closest - center) < radius * radius;
}

struct ShadowScene {
  vec3 center{0.0f, 0.8f, 0.0f};
  float radius = 0.5f;
  ImageObject ball, ground;
  ShadowScene() {
    ball = sphere(center, radius, 12000);
    ground = sheet(vec3(0.0f), vec3(0, 0, 1), vec3(1, 0, 0), 2.0f, 0.02f, 3);
  }
};

// A point light over a sphere over a plane: the plane's points in the shadow texture are lit
// exactly where the analytic shadow says, and so are the pixels that show them.
TEST(PointImage, ShadowTextureMatchesTheAnalyticShadow) {
  ShadowScene scene;
  const ImageLight light{vec3(0.4f, 3.0f, 0.2f)};
  PointImageRenderer renderer({scene.ball, scene.ground});
  ImageCamera camera;
  camera.eye = vec3(0.0f, 3.5f, 3.5f);
  camera.target = vec3(0.0f, 0.3f, 0.0f);
  camera.width = camera.height = 256;
  ImageSettings settings;
  settings.shadows = true;
  settings.shadowResolution = 1024;
  settings.layerGap = 0.08f;
  const ImageResult result = renderer.render(camera, std::span(&light, 1), settings);
  const std::vector<float>& m = renderer.shadowTexture();
  const size_t first = scene.ball.positions.size();
  size_t plane = 0, agree = 0, shadowed = 0;
  for (size_t k = 0; k < result.points.size(); ++k) {
    const uint32_t i = result.points[k];
    if (i == kNone || i < first) continue;
    const vec3 p = scene.ground.positions[i - first];
    const bool dark = blocked(p, light.position, scene.center, scene.radius);
    ++plane;
    shadowed += dark;
    agree += (m[i] < 0.5f) == dark;
  }
  ASSERT_GT(plane, 20000u);
  EXPECT_GT(shadowed, 1000u);
  EXPECT_GE(double(agree) / double(plane), 0.97);
  // Every point of the plane, seen or not.
  size_t all = 0;
  for (size_t i = 0; i < scene.ground.positions.size(); ++i)
    all += (m[first + i] < 0.5f) == blocked(scene.ground.positions[i], light.position,
                                             scene.center, scene.radius);
  EXPECT_GE(double(all) / double(scene.ground.positions.size()), 0.97);
  // The lit half of the sphere is lit: points facing the light see it.
  size_t facing = 0, facingLit = 0;
  for (size_t i = 0; i < first; ++i) {
    if (glm::dot(scene.ball.normals[i], glm::normalize(light.position - scene.ball.positions[i])) < 0.2f)
      continue;
    ++facing;
    facingLit += m[i] > 0.5f;
  }
  EXPECT_GE(double(facingLit) / double(facing), 0.99);
  // The same light and points again: the texture is kept.
  const ImageResult again = renderer.render(camera, std::span(&light, 1), settings);
  EXPECT_TRUE(again.stats.shadowsReused);
  EXPECT_EQ(again.color, result.color);
}

// An area light: the plane's shadow-texture values follow the analytic penumbra, the fraction of
// the light's square that a point sees past the sphere (integrated on a fine grid).
TEST(PointImage, AreaLightGivesTheAnalyticPenumbra) {
  ShadowScene scene;
  ImageLight light;
  light.position = vec3(0.0f, 2.5f, 0.0f);
  light.u = vec3(0.8f, 0.0f, 0.0f);
  light.v = vec3(0.0f, 0.0f, 0.8f);
  light.samples = 32;
  PointImageRenderer renderer({scene.ball, scene.ground});
  ImageCamera camera;
  camera.eye = vec3(0.0f, 3.0f, 3.0f);
  camera.width = camera.height = 64;
  ImageSettings settings;
  settings.shadows = true;
  settings.shadowResolution = 1024;
  settings.layerGap = 0.08f;
  renderer.render(camera, std::span(&light, 1), settings);
  const std::vector<float>& m = renderer.shadowTexture();
  const size_t first = scene.ball.positions.size();
  // The profile along x (|z| < 0.03), in bins 0.1 wide from the center outward.
  constexpr int kBins = 16;
  std::vector<double> measured(kBins, 0.0), analytic(kBins, 0.0);
  std::vector<int> count(kBins, 0);
  for (size_t i = 0; i < scene.ground.positions.size(); ++i) {
    const vec3 p = scene.ground.positions[i];
    if (std::abs(p.z) > 0.03f || p.x < 0.0f || p.x >= 1.6f) continue;
    const int bin = int(p.x / 0.1f);
    constexpr int kGrid = 48;
    int seen = 0;
    for (int b = 0; b < kGrid; ++b)
      for (int a = 0; a < kGrid; ++a) {
        const vec3 q = light.position + ((float(a) + 0.5f) / kGrid - 0.5f) * light.u +
                       ((float(b) + 0.5f) / kGrid - 0.5f) * light.v;
        seen += !blocked(p, q, scene.center, scene.radius);
      }
    measured[bin] += m[first + i];
    analytic[bin] += double(seen) / double(kGrid * kGrid);
    ++count[bin];
  }
  double worst = 0.0;
  bool umbra = false, penumbra = false, full = false;
  for (int b = 0; b < kBins; ++b) {
    ASSERT_GT(count[b], 0);
    const double a = analytic[b] / count[b];
    worst = std::max(worst, std::abs(measured[b] / count[b] - a));
    umbra |= a < 0.05;
    penumbra |= a > 0.2 && a < 0.8;
    full |= a > 0.99;
  }
  EXPECT_TRUE(umbra && penumbra && full) << "the profile does not cross the penumbra";
  EXPECT_LT(worst, 0.05);
}

TEST(PointImage, RefusesWhatItCannotDraw) {
  ImageObject none;
  none.positions.push_back(vec3(0.0f));
  EXPECT_THROW(PointImageRenderer({none}), UsageError);
  ImageObject one = sphere(vec3(0.0f), 1.0f, 100);
  PointImageRenderer renderer({one});
  ImageSettings settings;
  settings.layers = 0;
  EXPECT_THROW(renderer.render(ImageCamera{}, {}, settings), UsageError);
  settings.layers = 1;
  settings.shadows = true;
  const ImageLight inside{vec3(0.1f, 0.0f, 0.0f)};
  EXPECT_THROW(renderer.render(ImageCamera{}, std::span(&inside, 1), settings), UsageError);
}

}  // namespace
}  // namespace iso::viewer
