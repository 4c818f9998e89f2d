// The scene of a light bake, and its report (tools/iso/light_bake.h).
#include "tools/iso/light_bake.h"

#include <fmt/core.h>

#include "iso/error.h"
#include "tools/iso/text.h"
#include "viewer/scene.h"

namespace iso::cli {

LightBakeOptions lightBakeFromScene(const std::string& path, int bounces, int rays) {
  viewer::Scene scene;
  viewer::loadScene(path, scene);
  if (scene.lights.empty())
    throw UsageError(path + ": the scene has no lights to bake (\"lights\": [...])");
  LightBakeOptions options;
  options.enabled = true;
  options.bounces = bounces;
  options.rays = rays;
  options.color = scene.material.color;
  options.diffuse = scene.material.diffuse;
  for (const viewer::LightSpec& l : scene.lights) {
    BakeLight light;
    light.area = l.area;
    light.position = {l.position[0], l.position[1], l.position[2]};
    light.u = {l.u[0], l.u[1], l.u[2]};
    light.v = {l.v[0], l.v[1], l.v[2]};
    light.radiance = {l.color[0] * l.intensity, l.color[1] * l.intensity,
                      l.color[2] * l.intensity};
    light.inverseSquare = l.inverseSquare;
    light.samples = l.area ? l.samples : 1;
    options.lights.push_back(light);
  }
  return options;
}

void addLightBakeOptions(CLI::App* command, int& bounces, int& rays, CLI::Option* needs) {
  CLI::Option* b = command->add_option(
      "--bounces", bounces, "Diffuse bounces of the baked light after the direct light (0 to 16)");
  b->capture_default_str();
  CLI::Option* r = command->add_option("--bake-rays", rays,
                                       "Rays a corner traces for each bounce (1 to 4096)");
  r->capture_default_str();
  if (needs) {
    b->needs(needs);
    r->needs(needs);
  }
}

void printLightBake(const nlohmann::json& l) {
  const auto& e = l["direct_error"];
  fmt::print(
      "  light bake: {} corners ({} lit as their own leaf's side), {} shadow rays, {} bounce{} of "
      "{} rays a corner; mean irradiance {:.4g} {:.4g} {:.4g}\n",
      withSeparators(l["receivers"].get<uint64_t>()),
      withSeparators(l["own_corners"].get<uint64_t>()),
      withSeparators(l["shadow_rays"].get<uint64_t>()), l["bounces"].get<int>(),
      l["bounces"].get<int>() == 1 ? "" : "s", l["rays_per_corner"].get<int>(),
      l["mean_irradiance"][0].get<double>(), l["mean_irradiance"][1].get<double>(),
      l["mean_irradiance"][2].get<double>());
  fmt::print(
      "  light map error (direct light drawn from the corners against traced at {} points of the "
      "surface, of the mean): RMS {:.4f}, 95% {:.4f}, max {:.4f}\n",
      withSeparators(e["samples"].get<uint64_t>()), e["rms"].get<double>(),
      e["p95"].get<double>(), e["max"].get<double>());
  if (l.contains("timing")) {
    const auto& t = l["timing"];
    fmt::print("  light bake time: direct {:.2f} s, bounces {:.2f} s ({:.2f} s per million corners "
               "a bounce, {} rays/s)\n",
               t["direct_seconds"].get<double>(), t["bounce_seconds"].get<double>(),
               t["seconds_per_million_corners_per_bounce"].get<double>(),
               withSeparators(uint64_t(t["bounce_rays_per_second"].get<double>())));
  }
}

}  // namespace iso::cli
