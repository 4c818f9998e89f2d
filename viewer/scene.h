// What the viewer draws besides the surface: camera, lights, material, environment and the
// rendering switches, in world units (those of the scanned points). Set from a JSON scene file
// (specs/viewer.md, "Scene files") and command-line options, and turned into the shaders'
// FrameParams in frame units.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "iso/error.h"
#include "iso/format.h"
#include "base/text.h"
#include "shaders/shared.h"
#include "tracer/blob.h"

namespace iso::viewer {

using Vec3d = glm::dvec3;

struct Camera {
  Vec3d eye{}, target{}, up{0, 1, 0};
  double fovDegrees = 40.0;
};

struct LightSpec {
  bool area = false;
  Vec3d position{};  // point light, or the center of an area light
  Vec3d u{}, v{};    // area light edges
  std::array<float, 3> color{1, 1, 1};
  float intensity = 1.0f;
  int samples = 16;  // area light shadow rays per sample
  // The light falls off as 1 / r² (r in world units; "falloff": "inverse_square"), else it does
  // not fall off ("none", the default).
  bool inverseSquare = false;
};

struct Material {
  std::array<float, 3> color{0.75f, 0.75f, 0.72f};  // linear, when the file has no colors
  float diffuse = 0.9f, specular = 0.25f, shininess = 40.0f;
  float reflectivity = 0.0f, transparency = 0.0f, ior = 1.5f;
  std::array<float, 3> absorption{0, 0, 0};  // per world unit, inside
};

// What camera rays do at a back face (reached from the inside, f < 0, as an open scan seen from
// behind): shade it with the flipped normal, also tint it, or pass through it.
enum class BackFaces { Show, Tint, Hide };
inline constexpr NameTable<BackFaces, 3> kBackFaceNames{
    {{"show", BackFaces::Show}, {"tint", BackFaces::Tint}, {"hide", BackFaces::Hide}}};
// A name of kBackFaceNames; UsageError naming the accepted words otherwise.
BackFaces parseBackFaces(const std::string& text);

// What rays meet: the surface, the kept points as splats, or both (the nearer hit).
// What lights the diffuse term of a file with baked lighting (iso bake): its baked irradiance
// (no shadow rays; specular highlights live), the lights as for any file, or both added. Auto:
// baked when the file has lighting chunks.
enum class Lighting { Auto, Baked, Live, Both };
inline constexpr NameTable<Lighting, 4> kLightingNames{{{"auto", Lighting::Auto},
                                                        {"baked", Lighting::Baked},
                                                        {"live", Lighting::Live},
                                                        {"both", Lighting::Both}}};

enum class Draw { Surface, Points, Both };
inline constexpr NameTable<Draw, 3> kDrawNames{
    {{"surface", Draw::Surface}, {"points", Draw::Points}, {"both", Draw::Both}}};

// Caustic photons a light at most (all lights' photons are counted in 32 bits).
inline constexpr uint32_t kMaxCausticPhotons = 256u << 20;

// Image-space points (iso view --draw image): the scene file's "image" object, then the command
// line.
struct ImageScene {
  int layers = 1;              // depth-peeled layers blended front to back
  double layerGap = 0.0;       // d̃ in world units (0: a few point spacings, from the data)
  std::vector<float> opacity;  // one an input file, in (0, 1] (empty: opaque)
  int shadowSamples = 0;       // samples of each light for soft shadows (0: the lights' own)
  bool eyeDome = false;        // normal-free shading from the depth alone
};
inline constexpr int kMaxImageLayers = 64;
inline constexpr int kMaxImageShadowSamples = 64;

// Volumes from scattered data inside a point set surface (iso view --draw pss
// --volume-points): the scene file's "volume" object.
struct VolumeScene {
  // Control points (value, r, g, b, extinction per world unit), by increasing value; empty: a
  // ramp over the values' range (volumeTransfer, pss_view.cpp).
  std::vector<std::array<float, 5>> transfer;
  double smoothing = 0.0;  // the Gaussian's r, world units (0: the points' typical spacing)
  double step = 0.0;       // the integration's step (0: r)
};

struct Scene {
  std::optional<Camera> camera;      // none: framed on the surface's bounds
  std::optional<double> fovDegrees;  // overrides the camera's field of view
  std::vector<LightSpec> lights;     // none: one point light over the camera's shoulder
  Material material;
  std::array<float, 3> ambient{0.12f, 0.12f, 0.13f};
  std::array<float, 3> skyTop{0.55f, 0.66f, 0.85f}, skyBottom{0.18f, 0.17f, 0.16f};
  std::optional<Vec3d> up;  // none: from the file (z for LiDAR inputs, else y)
  std::string environment;  // an image OpenImageIO reads (equirectangular)
  float environmentIntensity = 1.0f;
  bool shadows = true, reflections = true, refractions = true;
  int bounces = 3;
  int samples = 1;         // per pixel (supersampling)
  float lodPixels = 1.0f;  // screen-space error allowed, pixels
  BackFaces backFaces = BackFaces::Show;
  Lighting lighting = Lighting::Auto;
  Draw draw = Draw::Surface;
  // A diffuse ground plane across the scene's up axis at this height (world units, along up),
  // seen from above; none when unset.
  std::optional<double> groundHeight;
  bool groundAuto = false;  // a ground just under the surface's bounds (completeScene)
  std::array<float, 3> groundColor{0.6f, 0.6f, 0.58f};
  // Caustic photons traced from each light onto the ground (shaders/caustics.h); 0: none. A
  // scene with caustics and no ground gets one under the surface (completeScene).
  uint32_t caustics = 0;
  std::array<float, 3> backTint{1.0f, 0.45f, 0.35f};  // multiplies back faces' color (Tint)
  ImageScene image;
  VolumeScene volume;
};

// Read a scene file over `scene` (keys it does not set stay). Throws iso::FileError naming the
// file and the key for anything it does not understand.
void loadScene(const std::filesystem::path& path, Scene& scene);

// Parse "a,b,c,..." (exactly count finite numbers), "x,y,z" and light specs for the command line;
// UsageError naming `what` on error.
std::vector<double> parseNumbers(const std::string& text, size_t count, const std::string& what);
Vec3d parseVec3(const std::string& text);
// "point:X,Y,Z[:R,G,B[:INTENSITY]]" or "area:X,Y,Z:UX,UY,UZ:VX,VY,VZ[:SAMPLES[:R,G,B[:I]]]".
LightSpec parseLight(const std::string& text);

// A unit vector along v; UsageError for a zero or non-finite v.
Vec3d normalized(const Vec3d& v);
// v turned by angle (radians) around the unit vector axis.
Vec3d rotated(const Vec3d& v, const Vec3d& axis, double angle);

// Axis-aligned bounds in world units.
struct Bounds {
  Vec3d lo{}, hi{};
};

// A cube of surface (a cell of the coarsest chunk's deepest level, or a point) that the default
// camera looks at: its center and edge, world units.
struct SurfaceCell {
  Vec3d center{};
  double size = 0.0;
};

// The default view (specs/viewer.md, "Default view"): of the 26 axis and diagonal directions, the
// one from which the most cells are seen (nearest in a 128 × 128 grid, looking along the
// direction; a vertical direction tilted 20 degrees towards the front, so that `up` stays up;
// ties to the view from higher up), with the seen cells' extent filling 80 % of the picture's
// width or height, whichever it reaches first at this aspect (width / height). UsageError for no
// cells.
Camera defaultCamera(const std::vector<SurfaceCell>& cells, const Vec3d& up, double fovDegrees,
                     double aspect);
// The default light for a camera: above and to the left of it.
LightSpec defaultLight(const Camera& camera, const Bounds& bounds);

struct FrameSetup {
  uint32_t width = 0, height = 0;
  uint32_t frameNumber = 1;
  uint32_t topChunk = 0, chunkCount = 0;
  uint32_t poolWordsLog2 = 0, poolWords = 0;  // per pool buffer; all of them
  uint32_t environmentWidth = 0, environmentHeight = 0;
  BlobOptions blob;                            // what the corner records carry
  glm::vec3 contentLo{0.0f}, contentHi{1.0f};  // Asset::contentLo, contentHi
  bool swapRedBlue = false, requests = true;
  bool flatTraversal = false;  // the loop shape of the tracer (shaders/rays.h)
  bool tileCones = true;       // camera rays start where their tile's cone meets a node (cone.h)
  // The splat index's chunk (kNoParent: the file keeps no points) and the typical splat radius
  // (frame units; secondary rays leave splats half of it away).
  uint32_t splatIndex = kNoParent;
  float splatRadius = 0.0f;
  bool pss = false;  // a point set surface in the scene (kOptionPss)
};

// The shaders' parameters for a frame of `scene` (with its camera and lights set) in `frame`.
gpu::FrameParams frameParams(const Scene& scene, const Frame& frame, uint8_t maxLevel,
                             const FrameSetup& setup);
// Whether a frame's camera rays may leave reflected or refracted rays at their hits (the tracer's
// radiance(), shaders/shade.h: bounces left and a reflectivity or transparency that is on).
bool secondaryRays(const gpu::FrameParams& params);
// Whether its hits may leave refracted rays (bounces left and a transparency that is on): then a
// hit may leave two rays, which the wavefront does not follow.
bool refractionRays(const gpu::FrameParams& params);

}  // namespace iso::viewer
