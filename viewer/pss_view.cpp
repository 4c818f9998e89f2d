// `iso view FILE --draw pss --cpu` (image_view.h): the points as a point set surface, ray traced
// on the CPU (viewer/pss.h).
#include <fmt/core.h>

#include <chrono>
#include <glm/geometric.hpp>

#include "viewer/image.h"
#include "viewer/image_view.h"
#include "viewer/pss.h"

namespace iso::viewer {

int viewPssCpu(const ViewOptions& o, const PssViewOptions& pss, const ImageInputs& in) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  std::vector<glm::vec3> positions, normals, colors;
  std::vector<float> h;
  bool anyColors = false;
  for (const ImageObject& object : in.objects) anyColors |= !object.colors.empty();
  for (const ImageObject& object : in.objects)
    for (size_t i = 0; i < object.positions.size(); ++i) {
      positions.push_back(object.positions[i]);
      normals.push_back(object.normals.empty() ? glm::vec3(0.0f) : object.normals[i]);
      h.push_back(kPssSpacings * (object.spacings.empty() ? object.spacing : object.spacings[i]));
      if (anyColors) colors.push_back(object.colors.empty() ? object.color : object.colors[i]);
    }
  const size_t points = positions.size();
  const PssSurface surface(std::move(positions), std::move(normals), std::move(h));
  const double fit = std::chrono::duration<double>(Clock::now() - t0).count();

  const Scene& s = o.scene;
  const Camera camera = sceneCamera(s, in);
  PssRender r;
  r.eye = glm::vec3(camera.eye - in.origin);
  r.target = glm::vec3(camera.target - in.origin);
  r.up = glm::vec3(camera.up);
  r.fovDegrees = float(camera.fovDegrees);
  r.width = int(o.width);
  r.height = int(o.height);
  std::vector<LightSpec> lights = s.lights;
  if (lights.empty()) lights.push_back(defaultLight(camera, in.bounds));
  for (const LightSpec& l : lights)
    r.lights.push_back({glm::vec3(l.position - in.origin), l.intensity});
  r.shadows = s.shadows;
  r.material = glm::vec4(s.material.diffuse, s.material.specular, s.material.shininess,
                         s.refractions ? s.material.transparency : 0.0f);
  r.iors = pss.iors;
  r.ambient = s.ambient[1];
  r.color = glm::vec3(s.material.color[0], s.material.color[1], s.material.color[2]);
  r.exact = pss.exact;
  const auto t1 = Clock::now();
  const std::vector<glm::vec3> linear = renderPss(surface, colors, r);
  const double render = std::chrono::duration<double>(Clock::now() - t1).count();
  std::vector<uint32_t> pixels(linear.size());
  for (size_t i = 0; i < linear.size(); ++i) pixels[i] = imagePixelWord(linear[i]);
  writeImage(o.out, o.width, o.height, pixels);
  fmt::print("{} points from {} file{}{}, a point set surface fitted in {:.2f} s\n", points,
             in.names.size(), in.names.size() == 1 ? "" : "s",
             in.normalsEstimated ? " (normals estimated)" : "", fit);
  fmt::print("{}: {}x{} point set surface ({} mode) on the CPU reference, {:.2f} s ({:.2f} M "
             "camera rays/s)\n",
             o.out.string(), o.width, o.height, pss.exact ? "exact" : "fast", render,
             double(o.width) * o.height / render * 1e-6);
  return 0;
}

}  // namespace iso::viewer
