// Point set surfaces on the GPU (lavapipe in CI) against the CPU reference from the same source
// (shaders/pss_trace.h): a sphere and a torus-like pair of spheres, fast and exact, shadowed,
// and a glass sphere whose channels refract apart.
#include <gtest/gtest.h>

#include "tests/viewer/point_scenes.h"
#include "tests/viewer/test_gpu.h"
#include "viewer/point_image.h"
#include "viewer/pss.h"
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
  struct Case {
    const char* what;
    bool exact;
    float transparency;
    vec3 iors;
  };
  for (const Case& c : {Case{"fast", false, 0.0f, vec3(1.5f)}, Case{"exact", true, 0.0f, vec3(1.5f)},
                        Case{"glass, dispersion", false, 0.7f, vec3(1.5f, 1.52f, 1.54f)}}) {
    r.exact = c.exact;
    r.material.w = c.transparency;
    r.iors = c.iors;
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
