// What the point set surface views share (pss_view.cpp: the CPU reference, headless and bench;
// pss_window.cpp: the window): the scene made from the inputs, and a picture's settings.
#pragma once

#include <memory>
#include <vector>

#include "viewer/image_view.h"
#include "tracer/pss.h"
#include "viewer/scene.h"
#include "viewer/view.h"

namespace iso::viewer {

// The inputs' points as one surface (h: kPssSpacings of each point's spacing), their colors (none
// when no input has any), the volume inside it, and how long the fit took.
struct PssScene {
  std::unique_ptr<PssSurface> surface;
  std::vector<glm::vec3> colors;
  std::unique_ptr<PssVolume> volume;  // --volume-points, in the points' frame
  std::vector<PssTransferPoint> transfer;
  double fitSeconds = 0.0;
};

PssScene pssScene(const ImageInputs& in, const PssViewOptions& pss, const Scene& scene);
// The same at (world - base) / scale: lengths (h, the volume's smoothing and step, the transfer
// function's extinction) scaled too.
PssScene pssScene(const ImageInputs& in, const PssViewOptions& pss, const Scene& scene,
                  const glm::dvec3& base, double scale);

// The picture's camera, lights and material from o.scene, in the points' frame, o.width ×
// o.height.
PssRender pssRender(const ViewOptions& o, const PssViewOptions& pss, const ImageInputs& in,
                    const PssScene& scene, const Camera& camera);

// "N points from F files, a point set surface fitted in S s" and its volume, on stdout.
void printScene(const ImageInputs& in, const PssScene& s);

const char* modeName(const PssViewOptions& pss);  // "exact" or "fast"

}  // namespace iso::viewer
