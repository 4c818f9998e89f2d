// Point set surfaces on the GPU (lavapipe in CI) against the CPU reference from the same source
// (shaders/pss_trace.h): two spheres, one shadowing the other, fast and exact, in glass whose
// channels refract apart, with a volume inside, and half mirror.
#include <gtest/gtest.h>

#include "tests/viewer/point_scenes.h"
#include "tests/viewer/test_gpu.h"
#include "tracer/point_image.h"
#include "tracer/pss.h"
#include "viewer/pss_gpu.h"

namespace iso::viewer {
namespace {

using glm::vec3;

// The share of pixels whose channels differ by more than 8/255.
double differing(const std::vector<uint32_t>& gpu, const std::vector<vec3>& cpu) {
  size_t bad = 0;
  for (size_t i = 0; i < gpu.size(); ++i) {
    const uint32_t want = imagePixelWord(cpu[i]);
    for (int k = 0; k < 3; ++k)
      if (std::abs(int((gpu[i] >> (8 * k)) & 255) - int((want >> (8 * k)) & 255)) > 8) {
        ++bad;
        break;
      }
  }
  return double(bad) / double(gpu.size());
}

TEST(PssGolden, theGpuDrawsWhatTheCpuDraws) {
  // Two spheres, one in the other's shadow, the second colored per point.
  const ImageObject a = sphere(vec3(0.0f), 1.0f, 12'000), b = sphere(vec3(1.6f, -0.9f, -0.8f), 0.6f, 4'000);
  std::vector<vec3> positions = a.positions, normals = a.normals, colors;
  positions.insert(positions.end(), b.positions.begin(), b.positions.end());
  normals.insert(normals.end(), b.normals.begin(), b.normals.end());
  std::vector<float> h(a.positions.size(), 2.0f * a.spacing);
  h.resize(positions.size(), 2.0f * b.spacing);
  for (size_t i = 0; i < positions.size(); ++i)
    colors.push_back(i < a.positions.size() ? vec3(0.8f, 0.7f, 0.6f) : vec3(0.2f, 0.5f, 0.9f));
  const PssSurface surface(positions, normals, h);
  GpuPss gpu(test::testGpu(), surface, colors);
  PssRender r;
  r.eye = vec3(0.5f, 0.6f, 4.5f);
  r.width = 120;
  r.height = 96;
  r.lights.push_back({vec3(-3, 4, 5), 0.9f});
  r.background = vec3(0.1f, 0.1f, 0.2f);
  // A volume in the big sphere: values rising along x, emitting and absorbing.
  std::vector<vec3> inside;
  std::vector<float> values;
  for (float z = -1.0f; z <= 1.0f; z += 0.08f)
    for (float y = -1.0f; y <= 1.0f; y += 0.08f)
      for (float x = -1.0f; x <= 1.0f; x += 0.08f)
        if (x * x + y * y + z * z < 0.95f) {
          inside.push_back({x, y, z});
          values.push_back(0.5f + 0.5f * x);
        }
  const PssVolume volume(inside, values);
  const std::vector<PssTransferPoint> transfer = {{0.0f, vec3(0.1f, 0.2f, 0.9f), 0.2f},
                                                  {1.0f, vec3(1.0f, 0.8f, 0.1f), 2.0f}};
  struct Case {
    const char* what;
    bool exact;
    float transparency;
    vec3 iors;
    bool volume;
    float reflectivity = 0.0f;
  };
  for (const Case& c : {Case{"fast", false, 0.0f, vec3(1.5f), false},
                        Case{"exact", true, 0.0f, vec3(1.5f), false},
                        Case{"glass, dispersion", false, 0.7f, vec3(1.5f, 1.52f, 1.54f), false},
                        Case{"glass with a volume", false, 0.8f, vec3(1.3f), true},
                        Case{"mirror and glass", false, 0.4f, vec3(1.4f), false, 0.4f}}) {
    r.exact = c.exact;
    r.material.w = c.transparency;
    r.reflectivity = c.reflectivity;
    r.iors = c.iors;
    r.volume = c.volume ? &volume : nullptr;
    r.transfer = c.volume ? transfer : std::vector<PssTransferPoint>{};
    const std::vector<vec3> cpu = renderPss(surface, colors, r);
    const std::vector<uint32_t> pixels = gpu.render(r);
    ASSERT_EQ(pixels.size(), cpu.size());
    const double share = differing(pixels, cpu);
    size_t covered = 0;
    for (const vec3& p : cpu) covered += p != r.background;
    std::printf("point set surface, %s: %.4f %% of the pixels differ by more than 8/255 (%zu "
                "covered)\n",
                c.what, 100.0 * share, covered);
    EXPECT_LT(share, 0.005) << c.what;
    EXPECT_GT(covered, cpu.size() / 5) << c.what;
  }
  EXPECT_EQ(test::testGpu().validationErrors->load(), 0u) << "Vulkan validation errors";
}

}  // namespace
}  // namespace iso::viewer
