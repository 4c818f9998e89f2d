// Image-space point rendering (Dobrev, Rosenthal and Linsen): points projected to pixels, holes
// filled by image filters, layers peeled for transparency, shadow textures per point. This is
// the CPU reference: shaders/image.h compiled as C++, every step over every point or pixel, as
// the GPU runs it (specs/viewer.md, "Image-space points").
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

#include "shaders/shared.h"

namespace iso::viewer {

// One point cloud of a scene, in the scene's float frame (the caller's choice of origin).
struct ImageObject {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;  // empty, or one unit normal a point
  std::vector<glm::vec3> colors;   // empty (every point `color`), or linear RGB a point
  glm::vec3 color{0.75f, 0.75f, 0.72f};
  float opacity = 1.0f;
  float spacing = 0.0f;  // the distance between neighbouring points (> 0): the typical one
  std::vector<float> spacings;  // empty, or each point's own (> 0): the masks' radius follows it
  bool orientedNormals = true;  // normals face outward (false: estimated, either way): no culling
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
  bool reuseShadows = true;    // keep the last frame's shadow textures while the lights stay
  int shadowResolution = 0;    // the lights' square images, pixels across (0: from the spacing)
  int maxShadowResolution = 4096;  // ... at most this many when chosen from the spacing
  int maxFillRadius = 8;       // the masks' largest radius (pixels, ≤ kImageMaxFillRadius)
  int maxFillPasses = 24;      // a guard: filling stops when nothing changes, long before
  glm::vec3 ambient{0.15f};
  glm::vec3 background{0.0f};
  float diffuse = 0.85f, specular = 0.25f, shininess = 40.0f;
};

inline constexpr float kDefaultGapSpacings = 3.0f;
// A light's image has pixels this many point spacings wide where the points lie (by default).
inline constexpr float kShadowPixelSpacings = 1.0f;
// The shadow texture's depth window d̃ / |cos| grows at most to d̃ / this at grazing light.
inline constexpr float kShadowLeastCosine = 0.35f;

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

// The points of a scene as both renderers read them: object after object, each point's position
// and spacing, normal (zero: none) and color (linear RGB and its object's opacity), and their box.
class PointImageScene {
 public:
  explicit PointImageScene(std::span<const ImageObject> objects);

  size_t size() const { return positions_.size(); }
  const std::vector<glm::vec4>& positions() const { return positions_; }  // xyz, w: spacing
  const std::vector<glm::vec4>& normals() const { return normals_; }      // xyz, w: 0
  const std::vector<glm::vec4>& colors() const { return colors_; }
  glm::vec3 lo() const { return lo_; }
  glm::vec3 hi() const { return hi_; }
  bool normalsEverywhere() const { return normalsAll_; }    // every point has a normal
  bool orientedEverywhere() const { return orientedAll_; }  // ... facing outward (culling)
  float largestSpacing() const { return largestSpacing_; }
  float gap(const ImageSettings& settings) const;  // d̃ in world units

 private:
  std::vector<glm::vec4> positions_, normals_, colors_;
  bool normalsAll_ = true, orientedAll_ = true;
  float largestSpacing_ = 0.0f;
  glm::vec3 lo_{0.0f}, hi_{0.0f};
};

// The passes of a frame, the same for both renderers: the eye's parameters (kImagePeel is added
// for the layers after the first) and one pass a sample of each light.
struct ImagePlan {
  gpu::ImageParams eye{};
  std::vector<gpu::ImageParams> samples;  // light after light, sample after sample
  std::vector<uint32_t> light;            // the light of each sample
  float far = 0.0f;                       // the eye's far distance: depth 1
  int layers = 1;
  int fillPasses = 24;                    // background filling stops after at most this many
  int occludedPasses = 8;                 // occluded filling likewise
  bool shadows = false;
  bool reuseShadows = true;
};

// The plan of a frame; UsageError for what cannot be drawn (no layer, too many lights, a light
// too close to the points for one square view of them).
ImagePlan planImage(const PointImageScene& scene, const ImageCamera& camera,
                    std::span<const ImageLight> lights, const ImageSettings& settings);

// The linear color of a pixel as an sRGB8 RGBA word (alpha 255), as the GPU writes it.
uint32_t imagePixelWord(glm::vec3 linear);

class PointImageRenderer {
 public:
  explicit PointImageRenderer(std::vector<ImageObject> objects);
  ~PointImageRenderer();

  ImageResult render(const ImageCamera& camera, std::span<const ImageLight> lights,
                     const ImageSettings& settings);

  // The shadow texture of the last frame with shadows: per point and light, the fraction of the
  // light's samples that reach it (points ordered object after object).
  const std::vector<float>& shadowTexture() const { return shadow_; }
  const PointImageScene& scene() const { return scene_; }

 private:
  void computeShadows(const ImagePlan& plan, size_t lights, ImageStats& stats);

  PointImageScene scene_;
  std::vector<float> shadow_;
  std::vector<float> shadowKey_;
};

}  // namespace iso::viewer
