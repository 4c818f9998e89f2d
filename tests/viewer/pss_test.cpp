// Point set surfaces (tracer/pss.h) against analytic shapes and brute force: the exact mode's
// hits on a sampled sphere and torus lie within a tenth of a point spacing of the surface, the
// fast mode's within the trust radius (its distribution printed), and the grid finds the same
// first hit as every patch tested in turn, for rays from outside and from the surface (shadow and
// refraction rays).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <numbers>
#include <random>

#include "tracer/pss.h"

namespace iso::viewer {
namespace {

using glm::vec3;

struct Shape {
  std::vector<vec3> positions, normals;
  float spacing = 0.0f;
};

// n points on the unit sphere, a Fibonacci spiral (nearly uniform), with their normals.
Shape sphere(size_t n) {
  Shape s;
  const float golden = std::numbers::pi_v<float> * (3.0f - std::sqrt(5.0f));
  for (size_t i = 0; i < n; ++i) {
    const float z = 1.0f - 2.0f * (float(i) + 0.5f) / float(n);
    const float r = std::sqrt(1.0f - z * z), a = golden * float(i);
    s.positions.push_back({r * std::cos(a), r * std::sin(a), z});
    s.normals.push_back(s.positions.back());
  }
  s.spacing = std::sqrt(4.0f * std::numbers::pi_v<float> / float(n));
  return s;
}

constexpr float kMajor = 1.0f, kMinor = 0.4f;

// About n points on the torus of radii kMajor and kMinor around z, uniform by area (rejection).
Shape torus(size_t n) {
  Shape s;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 2.0f * std::numbers::pi_v<float>), w(0.0f, 1.0f);
  while (s.positions.size() < n) {
    const float a = u(rng), b = u(rng);
    // Area grows with the distance from the axis: accept in proportion to it.
    if (w(rng) * (kMajor + kMinor) > kMajor + kMinor * std::cos(b)) continue;
    const vec3 ring(std::cos(a), std::sin(a), 0.0f);
    const vec3 normal = std::cos(b) * ring + std::sin(b) * vec3(0, 0, 1);
    s.positions.push_back(kMajor * ring + kMinor * normal);
    s.normals.push_back(normal);
  }
  const float area = 4.0f * std::numbers::pi_v<float> * std::numbers::pi_v<float> * kMajor * kMinor;
  s.spacing = std::sqrt(area / float(n));
  return s;
}

float sphereDistance(const vec3& p) { return std::abs(glm::length(p) - 1.0f); }
float torusDistance(const vec3& p) {
  const float q = std::sqrt(p.x * p.x + p.y * p.y) - kMajor;
  return std::abs(std::sqrt(q * q + p.z * p.z) - kMinor);
}

// The surface's points, h = 2 spacings.
PssSurface surfaceOf(const Shape& s) {
  return PssSurface(s.positions, s.normals, std::vector<float>(s.positions.size(), 2.0f * s.spacing));
}

// A ray from a random point 3 away towards a random point within 0.9 of `aim`'s region.
struct Ray {
  vec3 o, d;
};
std::vector<Ray> rays(size_t n, uint32_t seed, float spread) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Ray> out;
  while (out.size() < n) {
    const vec3 o = 3.0f * glm::normalize(vec3(g(rng), g(rng), g(rng)));
    const vec3 target = spread * vec3(u(rng), u(rng), u(rng));
    out.push_back({o, glm::normalize(target - o)});
  }
  return out;
}

// The exact and fast modes' distances from the surface over `count` rays that hit.
// `surely` (when given) says which rays must hit.
void expectHitsOnTheSurface(const Shape& shape, float (*distance)(const vec3&), const char* name,
                            float spread, bool (*surely)(const Ray&) = nullptr) {
  const PssSurface surface = surfaceOf(shape);
  std::vector<float> fast, exact;
  size_t far = 0, misses = 0, projections = 0, wrongMisses = 0;
  const auto all = rays(100'000, 17, spread);
  for (const Ray& r : all) {
    PssHit a, b;
    const bool hitFast = surface.intersect(r.o, r.d, 0.0f, 10.0f, PssMode::Fast, a);
    const bool hitExact = surface.intersect(r.o, r.d, 0.0f, 10.0f, PssMode::Exact, b);
    if (!hitFast || !hitExact) {
      ++misses;
      wrongMisses += surely && surely(r);
      continue;
    }
    fast.push_back(distance(r.o + a.t * r.d) / shape.spacing);
    exact.push_back(distance(r.o + b.t * r.d) / shape.spacing);
    far += exact.back() > 0.1f;
    projections += size_t(b.projections);
  }
  ASSERT_GT(fast.size(), all.size() / 4) << name;
  std::sort(fast.begin(), fast.end());
  std::sort(exact.begin(), exact.end());
  const auto at = [](const std::vector<float>& v, double q) { return v[size_t(q * (v.size() - 1))]; };
  std::printf("%s: %zu hits (%zu rays missed): exact within 0.1 spacing on %.4f %% (median %.5f, "
              "99.9 %% %.4f, max %.4f spacings; %.2f projections a hit); fast median %.4f, "
              "99 %% %.4f, max %.4f spacings (trust radius %.2f)\n",
              name, exact.size(), misses, 100.0 * (1.0 - double(far) / exact.size()),
              at(exact, 0.5), at(exact, 0.999), exact.back(), double(projections) / exact.size(),
              at(fast, 0.5), at(fast, 0.99), fast.back(), surface.options().trust * 2.0f);
  EXPECT_LE(double(far), 0.001 * exact.size()) << name;
  EXPECT_EQ(wrongMisses, 0u) << name;
  EXPECT_LE(fast.back(), surface.options().trust * 2.0f) << name;  // in spacings (h = 2)
}

// Whether a ray passes within 0.98 of the unit sphere's centre (then it must hit).
bool hitsTheSphere(const Ray& r) {
  const vec3 closest = r.o - glm::dot(r.o, r.d) * r.d;
  return glm::length(closest) < 0.98f;
}

TEST(Pss, exactHitsLieWithinATenthOfASpacingOfASphere) {
  expectHitsOnTheSurface(sphere(20'000), sphereDistance, "sphere", 0.9f, hitsTheSphere);
}

TEST(Pss, exactHitsLieWithinATenthOfASpacingOfATorus) {
  expectHitsOnTheSurface(torus(30'000), torusDistance, "torus", 1.3f);
}

// Rays that graze a noisy sphere (points 0.3 spacings off it at random): every exact-mode hit is
// near the MLS surface (projecting it moves it less than a quarter spacing; grazing hits that use
// up their 8 projections stop within 0.2): a ray whose projections leave every polynomial it
// meets misses, rather than keeping a hit that never converged (up to the trust radius, 1.5
// spacings, outside the silhouette); and rays that pass the sphere by more than a spacing miss.
TEST(Pss, grazingRaysHitTheSurfaceOrMissIt) {
  Shape shape = sphere(20'000);
  std::mt19937 rng(23);
  std::normal_distribution<float> g(0.0f, 1.0f);
  for (vec3& p : shape.positions) p *= 1.0f + 0.3f * shape.spacing * g(rng);
  const PssSurface surface = surfaceOf(shape);
  std::uniform_real_distribution<float> pass(1.0f - 2.0f * shape.spacing,
                                             1.0f + 2.0f * shape.spacing);
  size_t hits = 0, unconverged = 0, wrongHits = 0, outside = 0;
  float largest = 0.0f;
  for (int k = 0; k < 20'000; ++k) {
    // A ray along a random direction d whose closest approach to the centre is b.
    const vec3 d = glm::normalize(vec3(g(rng), g(rng), g(rng)));
    const vec3 side = glm::normalize(glm::cross(d, vec3(g(rng), g(rng), g(rng))));
    const float b = pass(rng);
    const vec3 o = b * side - 3.0f * d;
    const bool beyond = b > 1.0f + shape.spacing;
    outside += beyond;
    PssHit hit;
    if (!surface.intersect(o, d, 0.0f, 10.0f, PssMode::Exact, hit)) continue;
    ++hits;
    wrongHits += beyond;
    vec3 onSurface(0.0f);
    const vec3 x = o + hit.t * d;
    const float moved = surface.project(x, onSurface) ? glm::length(onSurface - x) / shape.spacing
                                                      : 1e30f;
    unconverged += moved > 0.25f;
    largest = std::max(largest, moved);
  }
  std::printf("grazing rays: %zu hits, %zu more than a quarter spacing off the MLS surface (the "
              "largest projection %.3f spacings); %zu of %zu rays passing more than a spacing "
              "outside hit\n",
              hits, unconverged, double(largest), wrongHits, outside);
  ASSERT_GT(hits, 1000u);
  EXPECT_LE(double(unconverged), 0.001 * double(hits));
  EXPECT_LE(double(wrongHits), 0.001 * double(outside));
}

TEST(Pss, theGridFindsTheFirstHitThatEveryPatchGives) {
  const Shape shape = torus(8'000);
  const PssSurface surface = surfaceOf(shape);
  size_t same = 0, total = 0, hits = 0;
  std::mt19937 rng(9);
  std::normal_distribution<float> g(0.0f, 1.0f);
  // Primary rays, then secondary ones from the surface: towards a light (shadow rays) and bent
  // into it (refraction rays).
  for (const Ray& r : rays(3'000, 23, 1.3f)) {
    std::vector<Ray> batch = {r};
    PssHit first;
    if (surface.intersectAll(r.o, r.d, 0.0f, 10.0f, first)) {
      const vec3 p = r.o + first.t * r.d;
      batch.push_back({p, glm::normalize(vec3(2, 3, 4) - p)});
      batch.push_back({p, glm::normalize(glm::refract(r.d, first.normal, 1.0f / 1.5f))});
      batch.push_back({p, glm::normalize(vec3(g(rng), g(rng), g(rng)))});
    }
    for (const Ray& s : batch) {
      const float start = &s == &batch[0] ? 0.0f : 1e-3f * shape.spacing;
      PssHit a, b;
      const bool grid = surface.intersect(s.o, s.d, start, 10.0f, PssMode::Fast, a);
      const bool brute = surface.intersectAll(s.o, s.d, start, 10.0f, b);
      ++total;
      hits += brute;
      same += grid == brute && (!grid || std::abs(a.t - b.t) <= 1e-5f * (1.0f + b.t));
    }
  }
  std::printf("grid against every patch: %zu of %zu rays alike (%zu hit)\n", same, total, hits);
  EXPECT_GT(hits, total / 3);
  EXPECT_GE(double(same), 0.999 * double(total));
}

// Dispersion: a glass sphere of points with indices (1.50, 1.52, 1.54) bends rays entering it at
// 10° to 70° to the angles Snell's law gives each channel (against the analytic normal at the
// analytic hit).
TEST(Pss, aGlassSphereBendsEachChannelToSnellsAngle) {
  const Shape shape = sphere(20'000);
  const PssSurface surface = surfaceOf(shape);
  const float iors[3] = {1.50f, 1.52f, 1.54f};
  double worst = 0.0;
  for (int degrees = 10; degrees <= 70; degrees += 5) {
    // A ray in the xz-plane meeting the sphere at incidence `degrees` at azimuth 0.3.
    const float incidence = glm::radians(float(degrees));
    const vec3 normal = glm::normalize(vec3(std::cos(0.3f), std::sin(0.3f), 0.4f));
    vec3 side = glm::normalize(glm::cross(normal, vec3(0, 0, 1)));
    const vec3 d = -std::cos(incidence) * normal + std::sin(incidence) * side;
    const vec3 o = normal - 3.0f * d;
    for (int c = 0; c < 3; ++c) {
      vec3 p, n, bent;
      for (bool exact : {false, true}) {
        ASSERT_TRUE(pssRefract(surface, o, d, iors[c], exact, p, n, bent)) << degrees;
        const float expected = std::asin(std::sin(incidence) / iors[c]);
        const float angle = std::acos(std::clamp(glm::dot(bent, -normal), -1.0f, 1.0f));
        const double error = std::abs(angle - expected) / expected;
        worst = std::max(worst, error);
        EXPECT_LT(error, 0.005) << degrees << " degrees, channel " << c << (exact ? " exact" : " fast");
      }
    }
  }
  std::printf("refraction angles of R, G and B within %.4f %% of Snell's law\n", 100.0 * worst);
}

// A picture: the sphere's silhouette against the analytic one.
TEST(Pss, aPictureOfASphereShowsItsSilhouette) {
  const Shape shape = sphere(20'000);
  const PssSurface surface = surfaceOf(shape);
  PssRender render;
  render.eye = vec3(0.4f, 0.3f, 3.0f);
  render.width = render.height = 96;
  render.lights.push_back({vec3(3, 4, 5), 1.0f});
  const std::vector<vec3> pixels = renderPss(surface, {}, render);
  const vec3 forward = glm::normalize(render.target - render.eye);
  const vec3 right = glm::normalize(glm::cross(forward, render.up)), up = glm::cross(right, forward);
  const float t = std::tan(glm::radians(20.0f));
  size_t both = 0, either = 0;
  for (int y = 0; y < render.height; ++y)
    for (int x = 0; x < render.width; ++x) {
      const float sx = ((x + 0.5f) / render.width * 2.0f - 1.0f) * t;
      const float sy = (1.0f - (y + 0.5f) / render.height * 2.0f) * t;
      const Ray r{render.eye, glm::normalize(forward + sx * right + sy * up)};
      const vec3 closest = r.o - glm::dot(r.o, r.d) * r.d;
      const bool analytic = glm::length(closest) < 1.0f;
      const bool drawn = pixels[size_t(y) * render.width + x] != vec3(0.0f);
      both += analytic && drawn;
      either += analytic || drawn;
    }
  std::printf("sphere picture: silhouette IoU %.4f\n", double(both) / double(either));
  EXPECT_GT(double(both) / double(either), 0.99);
}

// Reflection: a half-mirror plane of points under a red sphere of points (every surface of the
// scene reflects half the light). A ray that meets the plane brings half of the plane's own light
// (what it brings with no reflection) and half of what the analytically reflected ray from the
// plane's point brings (the red sphere).
TEST(Pss, aMirrorOfPointsShowsWhatTheReflectedRaySees) {
  std::vector<vec3> positions, normals, colors;
  std::vector<float> h;
  for (int j = 0; j <= 200; ++j)
    for (int i = 0; i <= 200; ++i) {
      positions.push_back({-2.0f + 0.02f * i, -2.0f + 0.02f * j, 0.0f});
      normals.push_back({0, 0, 1});
      colors.push_back(vec3(0.5f));
      h.push_back(0.04f);
    }
  const Shape ball = sphere(8'000);
  for (size_t i = 0; i < ball.positions.size(); ++i) {
    positions.push_back(vec3(0.0f, 0.0f, 1.0f) + 0.5f * ball.positions[i]);
    normals.push_back(ball.normals[i]);
    colors.push_back(vec3(1.0f, 0.0f, 0.0f));
    h.push_back(2.0f * 0.5f * ball.spacing);
  }
  const PssSurface surface(positions, normals, h);
  PssRender r;
  r.lights.push_back({vec3(0.0f, -3.0f, 4.0f), 1.0f});
  r.background = vec3(0.0f, 0.0f, 1.0f);
  PssRender matte = r;
  r.reflectivity = 0.5f;
  // From above to the plane's point (0.3, 0, 0), whose reflection meets the ball.
  const vec3 o(0.9f, 0.0f, 1.6f), m(0.3f, 0.0f, 0.0f);
  const vec3 d = glm::normalize(m - o), reflected(d.x, d.y, -d.z);
  const vec3 seen = pssRay(surface, colors, r, o, d);
  const vec3 own = pssRay(surface, colors, matte, o, d);
  const vec3 mirrored = pssRay(surface, colors, r, m + 1e-3f * vec3(0, 0, 1), reflected);
  const vec3 expected = 0.5f * own + 0.5f * mirrored;
  std::printf("half mirror: (%.4f %.4f %.4f) against half its own and half the reflected ray's "
              "(%.4f %.4f %.4f)\n",
              seen.r, seen.g, seen.b, expected.r, expected.g, expected.b);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(seen[k], expected[k], 5e-3f) << k;
  EXPECT_GT(mirrored.r, 0.1f);                // the ball, lit
  EXPECT_LT(mirrored.b, 0.5f * 0.5f + 0.05f);  // some of the background, through the ball's mirror
}

// A volume: points on a grid inside the unit sphere (the surface, made fully transparent, is its
// boundary) carrying an analytic Gaussian blob, extinction proportional to the value and no
// emission: the light let through along random chords is the analytic transmittance within
// 10⁻³ at the default step.
TEST(Pss, aVolumeLetsThroughWhatTheAnalyticIntegralSays) {
  const Shape shape = sphere(20'000);
  const PssSurface surface = surfaceOf(shape);
  const float sigma = 0.5f, spacing = 0.025f, kappa = 0.5f;
  std::vector<vec3> positions;
  std::vector<float> values;
  for (float z = -1.0f; z <= 1.0f; z += spacing)
    for (float y = -1.0f; y <= 1.0f; y += spacing)
      for (float x = -1.0f; x <= 1.0f; x += spacing)
        if (x * x + y * y + z * z < 0.998f) {
          positions.push_back({x, y, z});
          values.push_back(std::exp(-(x * x + y * y + z * z) / (2.0f * sigma * sigma)));
        }
  const PssVolume volume(positions, values, 0.02f);
  PssRender r;
  r.material = glm::vec4(0.85f, 0.25f, 40.0f, 1.0f);  // all light goes through the surface
  r.iors = vec3(1.0f);
  r.background = vec3(1.0f);
  r.volume = &volume;
  r.transfer = {{0.0f, vec3(0.0f), 0.0f}, {1.0f, vec3(0.0f), kappa}};
  double worst = 0.0;
  size_t chords = 0;
  for (const Ray& ray : rays(300, 31, 0.7f)) {
    // The chord through the unit sphere.
    const float c = -glm::dot(ray.o, ray.d), b2 = glm::dot(ray.o, ray.o) - c * c;
    if (b2 > 0.8f) continue;
    const float half = std::sqrt(1.0f - b2);
    const double s = double(sigma) * std::sqrt(2.0);
    const double integral = kappa * std::exp(-b2 / (2.0 * sigma * sigma)) * sigma *
                            std::sqrt(std::numbers::pi / 2.0) *
                            (std::erf(half / s) - std::erf(-half / s));
    const double expected = std::exp(-integral);
    const vec3 color = pssRay(surface, {}, r, ray.o, ray.d);
    worst = std::max(worst, std::abs(double(color.g) - expected));
    ++chords;
  }
  std::printf("volume: %zu chords, transmittance within %.5f of the analytic (%zu points, step "
              "%.3f)\n",
              chords, worst, volume.size(), volume.step());
  EXPECT_GT(chords, 100u);
  EXPECT_LT(worst, 1e-3);
}

// Values beyond the transfer function's control points take the nearer end's color and
// extinction: a constant value of 5 over points (0.2, 0.6) emits and absorbs as 0.6 does.
TEST(Pss, aValueBeyondTheTransferFunctionTakesItsEnd) {
  const Shape shape = sphere(20'000);
  const PssSurface surface = surfaceOf(shape);
  std::vector<vec3> positions;
  for (float z = -1.0f; z <= 1.0f; z += 0.05f)
    for (float y = -1.0f; y <= 1.0f; y += 0.05f)
      for (float x = -1.0f; x <= 1.0f; x += 0.05f)
        if (x * x + y * y + z * z < 0.998f) positions.push_back({x, y, z});
  const PssVolume volume(positions, std::vector<float>(positions.size(), 5.0f));
  PssRender r;
  r.material = glm::vec4(0.85f, 0.25f, 40.0f, 1.0f);
  r.iors = vec3(1.0f);
  r.volume = &volume;
  const vec3 red(0.9f, 0.1f, 0.05f);
  r.transfer = {{0.2f, vec3(0.0f, 0.0f, 1.0f), 0.1f}, {0.6f, red, 0.8f}};
  // Through the centre: a chord of 2.
  const vec3 color = pssRay(surface, {}, r, vec3(0.0f, 0.0f, 3.0f), vec3(0.0f, 0.0f, -1.0f));
  const float through = std::exp(-0.8f * 2.0f);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(color[k], (1.0f - through) * red[k], 2e-3f) << k;
}

}  // namespace
}  // namespace iso::viewer
