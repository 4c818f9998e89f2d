// The options of a conversion, for every stage: the command line's `iso convert` options
// (tools/iso/cmd_convert.cpp) and a few that only tests change. Validated by validateOptions
// (pipeline/convert/convert.h); written into the file's "parameters".
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "base/text.h"

namespace iso {

enum class OrientMode { Auto, Up, Propagate };
// The local surface fitted at a corner: the paper's plane, or an algebraic sphere (APSS,
// Guennebaud & Gross 2007), which has no curvature bias (specs/pipeline.md measures both).
enum class FitMode { Plane, Sphere };

inline constexpr NameTable<OrientMode, 3> kOrientNames{
    {{"auto", OrientMode::Auto}, {"up", OrientMode::Up}, {"propagate", OrientMode::Propagate}}};
inline constexpr NameTable<FitMode, 2> kFitNames{
    {{"sphere", FitMode::Sphere}, {"plane", FitMode::Plane}}};

// Where a texture is sampled: at every point (its colors then reach the corners as point colors
// do, averaged by the signed distance's weights), or at every corner's projection onto the zero
// set (the image's detail down to the leaf size, without the points' averaging).
enum class TextureAt { Points, Corners };
inline constexpr NameTable<TextureAt, 2> kTextureAtNames{
    {{"points", TextureAt::Points}, {"corners", TextureAt::Corners}}};

struct TextureOptions {
  std::filesystem::path image;  // empty: no texture
  double scale = 0.0;           // world units one repeat of the image spans; 0: the frame's size
  double sharpness = 4.0;       // P of the blend weights |n·axis|^P
  TextureAt at = TextureAt::Corners;
  bool enabled() const { return !image.empty(); }
};

struct OcclusionOptions {
  bool enabled = false;
  int rays = 32;        // per corner
  double radius = 0.0;  // world units a ray looks for the surface; 0: a tenth of the frame's size
};

// A light of a light bake, in world units. What a lit point receives is what the viewer's
// shading gives it (shaders/shade.h): radiance × max(cos θ, 0), over r² with inverseSquare,
// averaged over an area light's samples, 0 where the light is hidden.
struct BakeLight {
  bool area = false;
  std::array<double, 3> position{};      // a point light, or the center of an area light
  std::array<double, 3> u{}, v{};    // an area light's edges
  std::array<float, 3> radiance{1.0f, 1.0f, 1.0f};  // color × intensity
  bool inverseSquare = false;
  int samples = 16;        // an area light's samples at each corner (a stratified grid)
};

struct LightBakeOptions {
  bool enabled = false;  // iso convert --bake-light
  std::vector<BakeLight> lights;
  int bounces = 1;  // diffuse interreflection bounces after the direct light (0: direct only)
  int rays = 32;    // rays a corner for each bounce (cosine-weighted)
  // The diffuse reflectance is diffuse × the surface's color (the file's colors, else `color`),
  // as the viewer's diffuse term weighs it.
  std::array<float, 3> color{0.75f, 0.75f, 0.72f};
  float diffuse = 0.9f;
};

struct BuildOptions {
  int neighbors = 10;      // k of the k-NN radius r_i (and of PCA normals)
  double smoothing = 1.0;  // σ_i = smoothing · r_i
  FitMode fit = FitMode::Sphere;
  OrientMode orient = OrientMode::Auto;
  uint32_t leafPoints = 6;      // a node with more points may be subdivided
  // A node with more points is subdivided without a patch test. Not a command-line option: tests
  // lower it so that small scans have chunks many tested nodes wide, as large scans do.
  uint32_t maxTestedPoints = 4096;
  // A node wider than this many spacings is subdivided without a patch test, so that no test
  // reads points much farther than that from its node (out-of-core chunks need reads of bounded
  // reach). Not a command-line option.
  double maxTestedEdge = 128.0;
  int maxDepth = 20;            // deepest octree level (at most 20)
  double tolerance = 0.1;       // allowed patch error, in point spacings
  int cornerFit = 2;            // passes fitting leaf corners to the points (0: sampled values)
  // Keep every sheet the patches make, also across holes farther than trimReach radii of influence
  // from every point (a closed surface); false: the surface ends where the points end.
  bool fillHoles = false;
  double trimReach = 0.85;
  int normalBits = 8;           // octahedral normal bits per component: 8 or 12
  uint32_t chunkNodes = 32768;  // octree nodes per file chunk, about
  int zstdLevel = 3;
  bool removeOutliers = true;
  // Separate groups of fewer points (and less than half the points) are strays (points/points.h).
  uint32_t strayGroupPoints = 64;
  // Points per orientation block (orientNormals); part of the result, so a parameter.
  uint32_t orientBlockPoints = 1u << 20;
  // Points a chunk job of the octree stages owns, about (pipeline/convert/corner_stages.h): inputs
  // with more run as chunk jobs over cells of about this many points with their halos; part of the
  // result, so a parameter.
  uint32_t octreeChunkPoints = 1u << 21;
  TextureOptions texture;      // a triplanar texture baked into the colors (output/texture.h)
  OcclusionOptions occlusion;  // ambient occlusion baked into the corners (output/occlusion.h)
  LightBakeOptions lighting;   // light maps in lighting chunks (output/lighting.h)
  // The input points kept in points chunks (output/keep_points.h), positions to 2^-pointBits of the
  // frame.
  bool keepPoints = false;
  int pointBits = 24;
  // The scalar kept per point in values chunks (specs/iso-format.md, "Values chunks"): the name
  // of the points' one extra (the readers' ReadOptions::keepExtras), or "density" (the local point
  // density from each point's radius). Empty: none.
  std::string keepScalar;
  // Points per points chunk, about (kPointsPerChunk). Not a command-line option: tests lower it
  // so that small scans have many chunks.
  uint32_t keptPointsPerChunk = 1u << 16;
};

}  // namespace iso
