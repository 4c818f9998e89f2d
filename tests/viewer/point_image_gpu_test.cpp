// Image-space point rendering on the GPU (lavapipe in CI) against the CPU reference: the same
// plan and the same steps (shaders/image.h) give the same pictures and the same filling passes.
#include "viewer/point_image_gpu.h"

#include <gtest/gtest.h>

#include <cstdlib>

#include "point_scenes.h"
#include "test_gpu.h"

namespace iso::viewer {
namespace {

Gpu& imageGpu() { return test::testGpu(); }

// The share of pixels whose sRGB8 channels differ by more than 8 between the two pictures.
double differing(const std::vector<uint32_t>& gpu, const ImageResult& cpu) {
  size_t bad = 0;
  for (size_t i = 0; i < gpu.size(); ++i) {
    const uint32_t want = imagePixelWord(cpu.color[i]);
    for (int k = 0; k < 3; ++k)
      if (std::abs(int((gpu[i] >> (8 * k)) & 255) - int((want >> (8 * k)) & 255)) > 8) {
        ++bad;
        break;
      }
  }
  return double(bad) / double(gpu.size());
}

void expectSame(std::vector<ImageObject> objects, const ImageCamera& camera,
                std::span<const ImageLight> lights, const ImageSettings& settings,
                const char* what, const ImageCamera* before = nullptr) {
  PointImageRenderer cpu(objects);
  const ImageResult reference = cpu.render(camera, lights, settings);
  GpuPointImage gpu(imageGpu(), cpu.scene());
  // A frame drawn before from elsewhere leaves nothing in the next.
  if (before) gpu.render(*before, lights, settings);
  const GpuImageFrame frame = gpu.render(camera, lights, settings);
  ASSERT_EQ(frame.pixels.size(), size_t(camera.width) * camera.height);
  const double share = differing(frame.pixels, reference);
  std::printf("%s: %.4f %% of the pixels differ by more than 8/255\n", what, 100.0 * share);
  EXPECT_LT(share, 0.005) << what;
  // The same passes filled the first layer (the GPU counts every layer it was asked for).
  ASSERT_FALSE(reference.stats.backgroundPasses.empty()) << what;
  EXPECT_EQ(frame.stats.backgroundPasses.at(0), reference.stats.backgroundPasses.at(0)) << what;
  EXPECT_EQ(frame.stats.occludedPasses.at(0), reference.stats.occludedPasses.at(0)) << what;
  EXPECT_EQ(imageGpu().validationErrors->load(), 0u) << "Vulkan validation errors";
  // Not a blank picture: most of it is not the background.
  size_t covered = 0;
  for (float c : reference.coverage) covered += c > 0.5f;
  EXPECT_GT(covered, reference.coverage.size() / 10) << what;
}

TEST(ImageGolden, aSparseSphereIsFilledAlikeOnTheGpu) {
  ImageCamera camera;
  camera.eye = vec3(0.3f, 0.4f, 4.0f);
  camera.width = 200;
  camera.height = 160;
  const float pixel = 2.0f * std::tan(glm::radians(20.0f)) / 160.0f;
  const float spacing = 3.5f * pixel * 3.0f;
  const size_t n = size_t(4.0f * std::numbers::pi_v<float> / (spacing * spacing));
  const ImageLight light{vec3(3.0f, 4.0f, 5.0f)};
  expectSame({sphere(vec3(0.0f), 1.0f, n)}, camera, std::span(&light, 1), ImageSettings{},
             "sparse sphere");
}

TEST(ImageGolden, aFrameOwesNothingToTheFrameBefore) {
  // The sparse sphere from afar, after a frame that filled most of the image from close by.
  ImageCamera camera;
  camera.eye = vec3(0.3f, 0.4f, 6.0f);
  camera.width = 200;
  camera.height = 160;
  ImageCamera close = camera;
  close.eye = vec3(0.1f, -0.2f, 1.8f);
  const float pixel = 2.0f * std::tan(glm::radians(20.0f)) / 160.0f;
  const float spacing = 3.5f * pixel * 5.0f;
  const size_t n = size_t(4.0f * std::numbers::pi_v<float> / (spacing * spacing));
  const ImageLight light{vec3(3.0f, 4.0f, 5.0f)};
  expectSame({sphere(vec3(0.0f), 1.0f, n)}, camera, std::span(&light, 1), ImageSettings{},
             "sparse sphere after a close view", &close);
}

TEST(ImageGolden, peeledNestedSpheresBlendAlikeOnTheGpu) {
  ImageCamera camera;
  camera.eye = vec3(0.2f, 0.5f, 4.0f);
  camera.width = camera.height = 160;
  std::vector<ImageObject> objects;
  const float radii[3] = {1.0f, 0.65f, 0.3f};
  const vec3 colors[3] = {{0.2f, 0.3f, 0.9f}, {0.2f, 0.8f, 0.3f}, {0.6f, 0.35f, 0.2f}};
  const float opacities[3] = {0.3f, 0.5f, 1.0f};
  for (int s = 0; s < 3; ++s) {
    ImageObject o = sphere(vec3(0.0f), radii[s], size_t(60000 * radii[s] * radii[s]));
    o.color = colors[s];
    o.opacity = opacities[s];
    objects.push_back(std::move(o));
  }
  const ImageLight light{vec3(3.0f, 4.0f, 5.0f)};
  ImageSettings settings;
  settings.layers = 6;
  settings.cull = false;
  settings.layerGap = 0.15f;
  settings.antialias = ImageAntialias::Edges;
  settings.background = vec3(1.0f);
  expectSame(objects, camera, std::span(&light, 1), settings, "nested spheres, 6 layers");
}

TEST(ImageGolden, softShadowsAndEyeDomeShadingAlikeOnTheGpu) {
  ImageObject ball = sphere(vec3(0.0f, 0.8f, 0.0f), 0.5f, 12000);
  ImageObject ground = sheet(vec3(0.0f), vec3(0, 0, 1), vec3(1, 0, 0), 2.0f, 0.03f, 3);
  ImageCamera camera;
  camera.eye = vec3(0.0f, 3.5f, 3.5f);
  camera.target = vec3(0.0f, 0.3f, 0.0f);
  camera.width = camera.height = 160;
  ImageLight light;
  light.position = vec3(0.0f, 2.5f, 0.0f);
  light.u = vec3(0.8f, 0.0f, 0.0f);
  light.v = vec3(0.0f, 0.0f, 0.8f);
  light.samples = 6;
  ImageSettings settings;
  settings.shadows = true;
  settings.shadowResolution = 256;
  settings.layerGap = 0.08f;
  expectSame({ball, ground}, camera, std::span(&light, 1), settings, "soft shadows");
  ball.normals.clear();
  ground.normals.clear();
  settings.shadows = false;
  expectSame({ball, ground}, camera, {}, settings, "eye-dome shading");
}

}  // namespace
}  // namespace iso::viewer
