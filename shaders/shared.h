// Layouts and constants shared by the viewer's C++ code and its GLSL shaders (specs/viewer.md).
// Compiled as GLSL 4.50 and as C++20 (with GLM); viewer/gpu_layout.cpp static_asserts every size
// and offset below against the C++ structs so that the two never drift apart.
//
// Every struct holds only vec4/uvec4 members, so std140 and std430 give it the same layout.
#ifndef ISO_SHADERS_SHARED_H
#define ISO_SHADERS_SHARED_H

#ifdef __cplusplus
#include <cstdint>

#include <glm/glm.hpp>
namespace iso::gpu {
using glm::uvec4;
using glm::vec4;
using uint = uint32_t;
#define ISO_CONST inline constexpr
#else
#define ISO_CONST const
#endif

// The page pool: pages of 2^13 words (32 KiB) in up to kPoolBuffers buffers, read through their
// device addresses (FrameParams.poolAddress). A chunk takes consecutive pages of one buffer, so
// its words are read from one base address.
ISO_CONST uint kPageWordsLog2 = 13u;
ISO_CONST uint kPageWords = 1u << kPageWordsLog2;
ISO_CONST uint kPoolBuffers = 8u;
ISO_CONST uint kNotResident = 0xFFFFFFFFu;

// A chunk on the GPU ("blob"), in 32-bit words from its first word.
ISO_CONST uint kBlobNodeCount = 0u;    // nodes of the chunk
ISO_CONST uint kBlobWords = 1u;        // words of the blob
ISO_CONST uint kBlobNodes = 2u;        // holds the word of node 0 (even); node i is the 2 words 2i on
ISO_CONST uint kBlobData = 3u;         // holds the word of corner record 0 (even)
ISO_CONST uint kBlobHeaderWords = 4u;  // the node records follow
// Node records, read as one uvec2: word 0 = childMask (bits 0-7; 0 for a filled leaf) | kNodeCut
// | the node's geometric error code << kNodeErrorShift; word 1 = the first child's node index
// (internal node) or the word of the node's link list (cut node: a node whose children are roots
// of other chunks), 0 for a leaf. A link list is (chunk, root node index) per existing child in
// octant order. Node i's corner record is record i (every node has one: a leaf's patch, or an
// internal node's coarser patch drawn in place of its children). The error code e (8 bits) bounds
// the distance between the node's patch and the finest surface below it: 0 for none, else
// 2^((e - 128) / 8) node edges; 255 is never small enough.
ISO_CONST uint kNodeCut = 0x100u;
ISO_CONST uint kNodeErrorShift = 16u;
// Corner records: the 8 distances, then, when the file has them, 8 normals (octahedral snorm8
// pairs, 4 words), then, when it has colors or occlusion, 8 colors (sRGB RGB8, white without
// colors, and the occlusion as unorm8 alpha, 255 without it; 8 words). The distances are the file's
// own snorm8 codes (3 words: the codes of corners 0-3 and 4-7, a byte each, then per corner a
// 4-bit shift e: the distance in units of the node's cell is code / 127 · unit · 2^e, unit =
// FrameParams.surface.x), or, for files whose distances are not snorm8 (kOptionFloatDistances),
// float32 in units of the cell (8 words). Either way the tracer reads exactly the values
// SurfaceModel reads, scaled by a power of two.
ISO_CONST uint kRecordDistanceWords = 3u;
ISO_CONST uint kRecordFloatDistanceWords = 8u;
ISO_CONST uint kRecordNormalWords = 4u;
ISO_CONST uint kRecordColorWords = 8u;
// Then, when the file has lighting chunks (kOptionIrradiance), the 8 corners' baked irradiance as
// RGB9E5 (iso/lighting.h; a leaf's own corners' where its lighting chunk overrides them).
ISO_CONST uint kRecordIrradianceWords = 8u;

// Feedback from the shader, one buffer: the rays traced this frame by kind (camera rays, shadow
// rays, reflected and refracted rays), then per chunk the frame it was last requested, then per
// chunk the frame it was last used.
ISO_CONST uint kFeedbackPrimaryRays = 0u;
ISO_CONST uint kFeedbackShadowRays = 1u;
ISO_CONST uint kFeedbackSecondaryRays = 2u;
ISO_CONST uint kFeedbackPhotons = 3u;  // caustic photons traced (shaders/caustics.h)
ISO_CONST uint kFeedbackHeaderWords = 4u;

// The finest grid: 2^kGridLevels cells along an axis (the format's kMaxLevel).
ISO_CONST uint kGridLevels = 21u;
ISO_CONST float kGridSize = 2097152.0f;
ISO_CONST uint kGridMax = 2097151u;

// Rendering limits.
ISO_CONST uint kMaxLights = 4u;
ISO_CONST uint kRayStack = 8u;        // pending reflection/refraction rays per sample
ISO_CONST uint kMaxSteps = 4096u;     // cells one ray may visit (a guard, never a visible limit)
ISO_CONST uint kWorkgroupSize = 64u;  // one 8×8 tile of pixels, visited in Z-order
// A tile's cone of camera rays (cone.h): nodes it may look at, and nodes waiting on its stack.
ISO_CONST uint kConeNodes = 128u;
ISO_CONST uint kConeStack = 24u;
// A node is drawn in place of its children only when it spans at most this many pixels (its
// colors and normals are interpolated across it), besides its error being small enough.
ISO_CONST float kLodNodePixels = 2.0f;

// Bits of FrameParams.options.x.
ISO_CONST uint kOptionShadows = 1u;
ISO_CONST uint kOptionReflections = 2u;
ISO_CONST uint kOptionRefractions = 4u;
ISO_CONST uint kOptionNormals = 8u;       // the file has normals (else the gradient is used)
ISO_CONST uint kOptionColors = 16u;       // the file has colors (else the material's color)
ISO_CONST uint kOptionSwapRB = 32u;       // write BGRA (swapchains) instead of RGBA
ISO_CONST uint kOptionEnvironment = 64u;  // an environment map is bound
ISO_CONST uint kOptionRequests = 128u;    // rays request missing chunks (streaming on)
ISO_CONST uint kOptionOcclusion = 256u;   // the file has baked ambient occlusion
ISO_CONST uint kOptionBackTint = 512u;   // back faces seen by camera rays take FrameParams.backface
ISO_CONST uint kOptionBackHide = 1024u;  // camera rays pass through back faces
ISO_CONST uint kOptionFloatDistances = 2048u;  // records hold float32 distances, not codes
ISO_CONST uint kOptionFlatTraversal = 4096u;   // one loop of turns, not a loop of cells (rays.h)
ISO_CONST uint kOptionTileCones = 8192u;       // camera rays start where their tile's cone does
ISO_CONST uint kOptionSplats = 16384u;         // rays also meet the kept points as splats
ISO_CONST uint kOptionNoSurface = 32768u;      // rays do not meet the surface (splats alone)
ISO_CONST uint kOptionGround = 65536u;         // rays meet the ground plane (FrameParams.ground)
ISO_CONST uint kOptionPss = 131072u;           // rays meet a point set surface (trace.h, PssParams)
ISO_CONST uint kOptionIrradiance = 262144u;    // records carry baked irradiance (lighting chunks)
// --lighting (shade.h): the baked irradiance lights the diffuse term of the surface's hits, and
// the lights' own diffuse term and shadow rays are left out (baked), or kept too (both).
ISO_CONST uint kOptionBakedLight = 524288u;
ISO_CONST uint kOptionLiveLight = 1048576u;

// Splats (shaders/splats.h, specs/viewer.md "Splats"). A points chunk on the GPU ("splat blob"):
// word 0 the point count n, 1 the blob's words, 2 the levels of its box tree, 3 the word of point
// record 0; words 4 + l: the word of level l's first box, 20 + l: level l's box count. Level 0
// boxes bound the points 4i to 4i + 3 (in Morton order), level l > 0 boxes the boxes 4i to 4i + 3
// of level l - 1; the last level has one box. A box is 6 floats (lo xyz, hi xyz); a point record
// 6 words: center xyz and radius (floats, frame units), the normal (octahedral snorm16 pair), the
// color (sRGB RGB8, and 255 in the top byte when the normal is known, else 0).
ISO_CONST uint kSplatCount = 0u;
ISO_CONST uint kSplatLevels = 2u;
ISO_CONST uint kSplatPoints = 3u;
ISO_CONST uint kSplatLevelFirst = 4u;
ISO_CONST uint kSplatLevelCount = 20u;
ISO_CONST uint kSplatHeaderWords = 36u;
ISO_CONST uint kSplatMaxLevels = 16u;
ISO_CONST uint kSplatBranch = 4u;
ISO_CONST uint kSplatRecordWords = 6u;
ISO_CONST uint kSplatBoxWords = 6u;
// The splat index (one blob, the chunk FrameParams.splatIndex.x): word 0 its node count, 2 the
// word of node 0. Nodes in preorder (a node's subtree follows it); a node: its box (6 floats), its
// points chunk (kNotResident for a node that only groups others), `skip` (the node after its
// subtree), the chunk of its parent (kNotResident for none), the chunk's largest radius (float
// bits: the node is drawn in place of its children when that is below P.lod.x pixels).
ISO_CONST uint kSplatIndexNodes = 2u;
ISO_CONST uint kSplatNodeWords = 10u;

// Caustics (shaders/caustics.h, specs/viewer.md "Caustics"): the caustic map is a square grid of
// kCausticCells × kCausticCells cells over the ground plane, three words a cell (red, green, blue
// irradiance in units of 1 / kCausticScale, summed by atomic adds), cell (i, j) at words
// 3 (j · kCausticCells + i). A photon follows at most kPhotonBounces specular bounces.
ISO_CONST uint kCausticCells = 512u;
ISO_CONST float kCausticScale = 4096.0f;
ISO_CONST uint kPhotonBounces = 8u;

// Light kinds (Light.position.w).
ISO_CONST uint kLightNone = 0u;
ISO_CONST uint kLightPoint = 1u;
ISO_CONST uint kLightArea = 2u;

// A light in frame units. An area light is the parallelogram position ± u/2 ± v/2.
struct Light {
  vec4 position;  // xyz; w: kind
  vec4 color;     // rgb radiance × intensity; w: samples (area light)
  vec4 u;         // xyz: first edge (area light); w: 1 when it falls off as 1 / r² (frame units)
  vec4 v;         // xyz: second edge (area light)
};

// Everything a frame needs besides the chunks (uniform buffer, binding 0).
struct FrameParams {
  vec4 eye;        // xyz: camera position in frame units; w: the angle of one pixel (radians)
  vec4 right;      // xyz: camera right × tan(fov/2) × width/height
  vec4 up;         // xyz: camera up × tan(fov/2)
  vec4 forward;    // xyz: view direction, unit
  uvec4 image;     // width, height, samples per pixel, frame number
  uvec4 options;   // option bits, bounce limit, top chunk, chunk count
  uvec4 pool;      // log2 of the words per pool buffer, pool words, environment width, height
  vec4 lod;        // x: screen-space error (pixels) below which a coarser chunk is drawn; y: ray
                   // offset (frame units) against self-intersection; z: environment intensity;
                   // w: where shadow rays start counting blockers (frame units)
  vec4 ambient;    // rgb: ambient light
  vec4 albedo;     // rgb: material color (when the file has none); w: Phong exponent
  vec4 material;   // x: diffuse, y: specular, z: reflectivity, w: transparency
  vec4 medium;     // x: index of refraction; yzw: absorption per frame unit inside
  vec4 skyTop;     // rgb: sky color overhead (no environment map)
  vec4 skyBottom;  // rgb: sky color below the horizon
  vec4 worldUp;    // xyz: the scene's up direction (sky and environment map), unit
  vec4 backface;   // rgb: the tint of back faces (kOptionBackTint)
  vec4 surface;    // x: the unit of a distance code at level 0, float(√3 · the distance scale)
  Light lights[kMaxLights];
  uvec4 poolAddress[kPoolBuffers / 2u];  // device addresses of the pool buffers, two a vec4
  // The linear value of each 8-bit sRGB code i of the corner records' colors, at [i / 4][i % 4]
  // (a table: 24 powers a hit cost the CPU tracer 8 % of its time; setColorTable in blob.h).
  vec4 srgbToLinear[64];
  // Where the 8-bit sRGB code of a pixel's linear value rises: at [k / 4][k % 4] the least value
  // whose code is above k (k < 255; the last entry is unused), so that the GPU and the CPU encode
  // pixels alike, as the format's linearToSrgb8 does, without powers (setColorTable).
  vec4 srgbBounds[64];
  // The box that holds every node that is not empty, in frame units (xyz; the top chunk's leaves
  // and cut nodes and its deepest level's nodes): rays are clipped to it, grown by the widest node
  // their level of detail may draw (rays.h, intersect). The root cube when not known.
  vec4 contentLo;
  vec4 contentHi;
  // Splats: x the chunk of the splat index (kOptionSplats).
  uvec4 splatIndex;
  // x: the depth window of splat blending, in radii of the nearest splat.
  vec4 splat;
  // The ground (kOptionGround): the points p with dot(xyz, p) = w (frame units), xyz the scene's
  // up, seen from above; a diffuse plane of color groundColor (linear RGB).
  vec4 ground;
  vec4 groundColor;
  // Caustics: x photons traced from each light toward the disc (0: none), y the photons of all
  // lights (x times the lights, which come first in `lights`). The disc: center xyz and radius
  // w (frame units), across the direction from the light (it covers the content box). A point p
  // of the ground lies in map cell (dot(causticU.xyz, p) + causticU.w, dot(causticV.xyz, p) +
  // causticV.w), cells as wide as 1 / |causticU.xyz|.
  uvec4 caustics;
  vec4 causticDisc;
  vec4 causticU;
  vec4 causticV;
};

// Image-space point rendering (shaders/image.h, specs/viewer.md "Image-space points"): bits of
// ImageParams.image.w.
ISO_CONST uint kImageCull = 1u;        // points whose normal faces away are not drawn
ISO_CONST uint kImageShadows = 2u;     // shading reads each point's shadow texture value
ISO_CONST uint kImagePeel = 4u;        // a layer after the first: points must lie behind the last
ISO_CONST uint kImageEyeDome = 8u;     // normal-free shading from the depth alone
ISO_CONST uint kImageAaEdges = 16u;    // anti-aliasing also at the edges between layers
ISO_CONST uint kImageAaOff = 32u;      // no anti-aliasing
ISO_CONST uint kImageSmoothOff = 64u;  // no smoothing
ISO_CONST uint kImageOnlyLayer = 128u;  // GPU: the one layer: blending keeps nothing for the next
ISO_CONST uint kImageNoPoint = 0xFFFFFFFFu;  // a pixel no point covers
ISO_CONST uint kImageMaxFillRadius = 8u;
// The stages of shaders/image.comp.glsl (its specialization constant 0).
ISO_CONST uint kImageStageProject = 0u;    // a point into layer A (64-bit atomic minimum)
ISO_CONST uint kImageStageFill = 2u;       // one filling pass, layer A into layer B (ping-pong)
ISO_CONST uint kImageStageControl = 3u;    // whether the next filling pass runs
ISO_CONST uint kImageStageShade = 4u;      // layer A's pixels shaded
ISO_CONST uint kImageStageSmooth = 5u;     // smoothed, anti-aliased, blended under the layers
                                           // before (A kept as R), into the picture's pixels
ISO_CONST uint kImageStageLit = 9u;        // a point of a light's first layer counts as lit
ISO_CONST uint kImageStages = 10u;
// Words of the control buffer: the filling pass's indirect dispatch (x, y, z), the pixels the
// last pass changed, then the passes that changed something, of each kind, then the round of
// the filling under way (from 0).
ISO_CONST uint kImageControlChanged = 3u;
ISO_CONST uint kImageControlPasses = 4u;
ISO_CONST uint kImageControlRound = 6u;
ISO_CONST uint kImageControlTiles = 8u;  // 8 and 9: the tiles listed for rounds of each parity,
                                         // 10: those projection left a point in or next to,
                                         // 11: every tile any of them listed (for shading)
// Filling on the GPU runs over tiles of this many pixels square (an invocation a tile): the first
// round over all, each later one over the tiles where something within the masks' reach changed
// in the round before (at least kImageMaxFillRadius: a changed pixel wakes its tile and the
// eight around it).
ISO_CONST uint kImageFillTile = 8u;
ISO_CONST uint kImageControlWords = 8u;

// One pass of the image-space point renderer: the camera (the eye's or a light's), the image and
// the layer. Positions are world units relative to the scene's origin (the renderer's choice).
struct ImageParams {
  vec4 eye;       // xyz: the viewpoint; w: 1 / the far distance (depths are distance / far)
  vec4 toX;       // xyz: right / (tan(fov/2) · aspect): a point v from the eye is at
                  // dot(v, toX) / dot(v, forward) across the image, -1 left to +1 right
  vec4 toY;       // xyz: up / tan(fov/2): likewise, +1 at the top
  vec4 forward;   // xyz: the view direction, unit; w: the near distance
  uvec4 image;    // width, height, the masks' largest radius (pixels), option bits (kImage...)
  vec4 layer;     // x: the least gap between two layers (d̃) in depth units; y: the size of a
                  // pixel at distance 1 (2 tan(fov/2) / height); z: the least |cos| between a
                  // light's ray and a normal in the shadow offset; w: eye-dome strength
  vec4 ambient;   // rgb: ambient light; w: the light count
  vec4 material;  // x: diffuse, y: specular, z: Phong exponent; w: a light's pass: its light
  vec4 background;  // rgb: the background's linear color
  Light lights[kMaxLights];  // in the renderer's world units; color.w: the light's samples
};

// Point set surfaces (shaders/pss.h, pss_trace.h, pss.comp.glsl): a picture's camera, grid,
// material and lights. Positions are relative to the scene's origin.
ISO_CONST uint kPssMaxLights = 8u;
ISO_CONST uint kPssStorageBindings = 11u;  // a surface's and its volume's buffers (pss_buffers.h)
ISO_CONST uint kPssMaxTransfer = 8u;  // a volume's transfer function's control points at most
ISO_CONST uint kPssExact = 1u;    // image.z bits: camera and refracted rays in the exact mode
ISO_CONST uint kPssShadows = 2u;  // shadow rays
ISO_CONST uint kPssColors = 4u;   // the points have colors (else material color)
struct PssParams {
  vec4 eye;         // xyz: the viewpoint; w: the scene's size (ray offsets)
  vec4 right;       // xyz: right · tan(fov/2) · aspect
  vec4 up;          // xyz: up · tan(fov/2)
  vec4 forward;     // xyz: the view direction, unit
  vec4 gridLo;      // xyz: the grid's corner; w: its cells' side
  uvec4 gridDims;   // xyz: cells across; w: the light count
  uvec4 image;      // width, height, option bits (kPss...), 0
  vec4 settings;    // trust (b / h), reach (/ h), tolerance (/ h), projections at most
  vec4 material;    // diffuse, specular, shininess, transparency
  vec4 iors;        // indices of refraction of R, G, B; w: ambient
  vec4 color;       // rgb: the color of points without one; w: reflectivity
  vec4 background;  // rgb: the background's linear color
  vec4 lights[kPssMaxLights];  // xyz: position; w: intensity
  vec4 volumeLo;        // the volume's grid: xyz its corner; w: its cells' side
  uvec4 volumeDims;     // xyz: cells across; w: the transfer function's points (0: no volume)
  vec4 volumeSettings;  // smoothing r, reach, step, 0
  vec4 transfer[2u * kPssMaxTransfer];  // per control point (value, extinction, 0, 0), (color, 0)
};

// One chunk in the chunk table (binding 1).
struct ChunkEntry {
  uvec4 state;  // x: first pool page or kNotResident; y: the chunk's level; z: float bits of its
                // geometric error (frame units); w: parent chunk or kNotResident
};

#ifdef __cplusplus
}  // namespace iso::gpu
#endif
#endif  // ISO_SHADERS_SHARED_H
