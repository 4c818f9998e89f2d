// Image-space point rendering (Dobrev, Rosenthal and Linsen): points projected to pixels, holes
// filled by image filters, layers peeled for transparency, shadow textures per point. This is
// the CPU reference: shaders/image.h compiled as C++, every step over every point or pixel, as
// the GPU runs it (specs/viewer.md, "Image-space points").
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

namespace iso::viewer {

// One point cloud of a scene, in the scene's float frame (the caller's choice of origin).
struct ImageObject {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;  // empty, or one unit normal a point
  std::vector<glm::vec3> colors;   // empty (every point `color`), or linear RGB a point
  glm::vec3 color{0.75f, 0.75f, 0.72f};
  float opacity = 1.0f;
  float spacing = 0.0f;  // the distance between neighbouring points (> 0)
};

enum class ImageAntialias { Off, Silhouettes, Edges };

// A light: a point light, or an area light (the parallelogram center ± u/2 ± v/2) sampled at
// `samples` points, each a point light of its own shadow texture (Monte-Carlo soft shadows).
struct ImageLight {
  glm::vec3 position{0.0f};
  glm::vec3 color{1.0f};
  glm::vec3 u{0.0f}, v{0.0f};
  int samples = 1;
  bool area() const { return glm::dot(u, u) > 0.0f || glm::dot(v, v) > 0.0f; }
};

struct ImageCamera {
  glm::vec3 eye{0.0f, 0.0f, 1.0f}, target{0.0f}, up{0.0f, 1.0f, 0.0f};
  float fovDegrees = 40.0f;
  int width = 512, height = 512;
};

struct ImageSettings {
  int layers = 1;              // depth-peeled layers blended front to back
  float layerGap = 0.0f;       // d̃, the least distance between two surface layers (world
                               // units); 0: kDefaultGapSpacings times the largest spacing
  ImageAntialias antialias = ImageAntialias::Silhouettes;
  bool smooth = true;
  bool eyeDome = false;        // normal-free shading from depth (forced for clouds without normals)
  float eyeDomeStrength = 20.0f;
  bool cull = true;            // back-face culling of points with normals
  bool shadows = false;        // shadow textures for every light
  int shadowResolution = 1024; // the lights' square images
  int maxFillRadius = 8;       // the masks' largest radius (pixels, ≤ kImageMaxFillRadius)
  int maxFillPasses = 64;      // a guard: filling stops when nothing changes, long before
  glm::vec3 ambient{0.15f};
  glm::vec3 background{0.0f};
  float diffuse = 0.85f, specular = 0.25f, shininess = 40.0f;
};

inline constexpr float kDefaultGapSpacings = 3.0f;

struct ImageStats {
  int layers = 0;                        // layers that held points
  std::vector<int> backgroundPasses;     // filling passes that changed something, per layer
  std::vector<int> occludedPasses;
  uint64_t projected = 0;                // points projected, all passes (eye and lights)
  bool shadowsReused = false;            // the shadow textures of the last frame were kept
};

struct ImageResult {
  int width = 0, height = 0;
  std::vector<glm::vec3> color;      // linear RGB, blended over the background
  std::vector<float> coverage;       // the layers' blended opacity, 0 to 1
  std::vector<float> depth;          // the first layer's filled depth: distance (world), 0: none
  std::vector<uint32_t> points;      // the first layer's point per pixel (kImageNoPoint: none)
  ImageStats stats;
};

class PointImageRenderer {
 public:
  explicit PointImageRenderer(std::vector<ImageObject> objects);
  ~PointImageRenderer();

  ImageResult render(const ImageCamera& camera, std::span<const ImageLight> lights,
                     const ImageSettings& settings);

  // The shadow texture of the last frame with shadows: per point and light, the fraction of the
  // light's samples that reach it (points ordered object after object).
  const std::vector<float>& shadowTexture() const { return shadow_; }
  size_t pointCount() const { return positions_.size(); }
  float gap(const ImageSettings& settings) const;

 private:
  struct ShadowKey;
  void computeShadows(std::span<const ImageLight> lights, const ImageSettings& settings,
                      ImageStats& stats);

  std::vector<glm::vec3> positions_, normals_;
  std::vector<glm::vec4> colors_;  // linear RGB and the object's opacity
  std::vector<float> spacing_;
  bool normals_all_ = true;        // every object has normals
  float largestSpacing_ = 0.0f;
  glm::vec3 lo_{0.0f}, hi_{0.0f};
  std::vector<float> shadow_;
  std::vector<float> shadowKey_;
};

}  // namespace iso::viewer
