// `iso view --draw image`: point clouds drawn in image space (point_image.h), as a picture on the
// GPU (--headless) or the CPU reference (--cpu), or timed along an orbit (--bench). The caller
// reads the inputs (tools/iso/view_points.cpp): this layer gets their points.
#pragma once

#include <chrono>
#include <condition_variable>
#include <exception>
#include <memory>
#include <optional>
#include <mutex>
#include <vector>

#include "iso/format.h"
#include "tracer/point_image.h"
#include "viewer/scene.h"
#include "viewer/view.h"

namespace iso::viewer {

struct ImageInputs {
  std::vector<ImageObject> objects;  // one a file, in the frame of `origin`
  std::vector<std::string> names;    // the files
  Vec3d origin{0.0};                 // world position of the objects' (0, 0, 0)
  Bounds bounds;                     // world units
  Vec3d up{0, 1, 0};                 // the scene's default up (z for LAS inputs)
  bool normalsEstimated = false;     // some object's normals were estimated, not read
  double loadSeconds = 0.0;          // reading and preparing the points
  uint64_t pointsRead = 0;           // from the files (more than drawn: a subsample, --vram)
  std::string choice;                // how the points drawn were chosen, when not all are
  bool preview = false;              // what was read so far (a window draws it while reading)
  // What the default camera frames (sceneCamera), when not empty: a subsample of all the points
  // read (about kFramingPoints), each as wide as the points it stands for (else the objects'
  // points are framed, as many).
  std::vector<SurfaceCell> framing;
};
inline constexpr size_t kFramingPoints = 200000;

// The objects with the scene's opacity (one for all, or one an object; UsageError otherwise).
std::vector<ImageObject> withOpacity(const std::vector<ImageObject>& objects,
                                     const ImageScene& scene);

struct ImageViewOptions {
  ImageSettings settings;  // layers, layer gap and eye-dome shading come from the scene
  int fillRoundsPerSubmit = 0;  // GpuPointImage::setRoundsPerSubmit (0: its default)
};

// The scene's camera (framed on the points when it has none), lights (a point light made a small
// square one for the scene's shadow samples) and settings, for the points' frame.
// `aspect`: the picture's width / height.
Camera sceneCamera(const Scene& scene, const ImageInputs& inputs, double aspect);
ImageCamera cameraOf(const ImageInputs& inputs, const Camera& camera, uint32_t width,
                     uint32_t height);
std::vector<ImageLight> lightsOf(const Scene& scene, const ImageInputs& inputs,
                                 const Camera& camera);
ImageSettings settingsOf(const Scene& scene, const ImageViewOptions& image);
// ... with the lights' images no larger than --vram leaves room for beside `points`.
ImageSettings budgeted(ImageSettings settings, const ViewOptions& options, size_t points,
                       size_t lights);

// Each returns the process exit code and throws for errors.
int viewImageHeadless(const ViewOptions& options, const ImageViewOptions& image,
                      const ImageInputs& inputs);
int viewImageCpu(const ViewOptions& options, const ImageViewOptions& image,
                 const ImageInputs& inputs);
int viewImageBench(const ViewOptions& options, const ImageViewOptions& image,
                   const ImageInputs& inputs);

// Point set surfaces (--draw pss; tracer/pss.h): the points' h is this many of their spacings.
inline constexpr float kPssSpacings = 2.0f;
struct PssViewOptions {
  bool exact = false;          // --pss exact: camera and refracted rays projected onto the MLS surface
  glm::vec3 iors{1.5f};        // --ior: of R, G and B (dispersion when they differ)
  // --volume-points: scattered values inside the surface (world positions), none: empty inside.
  std::vector<glm::dvec3> volumePositions;
  std::vector<float> volumeValues;
};
// The points as a point set surface ray traced on the CPU reference, on the GPU, or timed along
// an orbit (pss_view.cpp).
int viewPssCpu(const ViewOptions& options, const PssViewOptions& pss, const ImageInputs& inputs);
int viewPssHeadless(const ViewOptions& options, const PssViewOptions& pss,
                    const ImageInputs& inputs);
int viewPssBench(const ViewOptions& options, const PssViewOptions& pss, const ImageInputs& inputs);
// The points as a point set surface among the objects of an .iso file's scene (ViewOptions::pss,
// `iso view FILE.iso --with-pss POINTS`), in its frame units (`frame`), with the volume inside.
std::shared_ptr<const PssObject> pssObject(const ImageInputs& inputs, const PssViewOptions& pss,
                                           const Scene& scene, const Frame& frame);
// In a window (pss_window.cpp): traced when the view or the scene changes, smaller while the
// camera moves.
int viewPssWindow(const ViewOptions& options, const PssViewOptions& pss, const ImageInputs& inputs);

// Points arriving while a window is open: a loader publishes what it has read (previews, then
// all of it, then the points of each view the window asks for), or its error; the window draws
// the latest.
class ImageFeed {
 public:
  void publish(ImageInputs&& inputs);
  void fail(std::exception_ptr error);
  // What was published since `version` (null when nothing new), moving `version` on; rethrows
  // the loader's error.
  std::shared_ptr<const ImageInputs> since(uint64_t& version) const;

  // The camera the window rests at, for a loader holding more points than it draws.
  struct View {
    Camera camera;
    uint32_t width = 0, height = 0;
  };
  void want(const View& view);
  // The latest view wanted and not yet taken, waiting at most `wait` for one.
  std::optional<View> wanted(std::chrono::milliseconds wait);

 private:
  mutable std::mutex mutex_;
  std::shared_ptr<const ImageInputs> latest_;
  uint64_t version_ = 0;
  std::exception_ptr error_;
  std::condition_variable viewChanged_;
  std::optional<View> wanted_;
};

// The window (image_window.cpp): draws the feed's latest points from the first preview on.
int viewImageWindow(const ViewOptions& options, const ImageViewOptions& image, ImageFeed& feed);

}  // namespace iso::viewer
