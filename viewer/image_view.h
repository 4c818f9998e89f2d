// `iso view --draw image`: point clouds drawn in image space (point_image.h), as a picture on the
// GPU (--headless) or the CPU reference (--cpu), or timed along an orbit (--bench). The caller
// reads the inputs (tools/iso/view_points.cpp): this layer gets their points.
#pragma once

#include <vector>

#include "viewer/point_image.h"
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
};

struct ImageViewOptions {
  ImageSettings settings;
  int shadowSamples = 0;  // samples of each area light (0: the scene's own)
  int fillRoundsPerSubmit = 0;  // GpuPointImage::setRoundsPerSubmit (0: its default)
};

// Each returns the process exit code and throws for errors.
int viewImageHeadless(const ViewOptions& options, const ImageViewOptions& image,
                      const ImageInputs& inputs);
int viewImageCpu(const ViewOptions& options, const ImageViewOptions& image,
                 const ImageInputs& inputs);
int viewImageBench(const ViewOptions& options, const ImageViewOptions& image,
                   const ImageInputs& inputs);

}  // namespace iso::viewer
