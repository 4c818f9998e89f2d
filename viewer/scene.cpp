// Scene files, command-line scene options and the shaders' frame parameters (scene.h).
#include "viewer/scene.h"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "iso/check.h"
#include "iso/error.h"
#include "tracer/splats.h"

namespace iso::viewer {
namespace {

using nlohmann::json;

}  // namespace

Vec3d normalized(const Vec3d& v) {
  const double n = glm::length(v);
  if (!(n > 0.0) || !std::isfinite(n)) throw UsageError("a zero or non-finite vector");
  return v / n;
}

Vec3d rotated(const Vec3d& v, const Vec3d& axis, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);  // Rodrigues' rotation formula
  return v * c + glm::cross(axis, v) * s + axis * (glm::dot(axis, v) * (1 - c));
}

std::vector<double> parseNumbers(const std::string& text, size_t count, const std::string& what) {
  if (std::optional<std::vector<double>> values = parseNumberList(text, count)) return *values;
  throw UsageError(what + ": expected " + std::to_string(count) + " finite number" +
                   (count == 1 ? "" : "s separated by commas") + ", not '" + text + "'");
}

namespace {

std::vector<std::string> split(const std::string& text, char sep) {
  std::vector<std::string> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, sep)) out.push_back(item);
  return out;
}

// Reading JSON values with errors that name the file and the key.
struct Fields {
  const std::string& file;
  [[noreturn]] void fail(const std::string& key, const std::string& why) const {
    throw FileError(file, std::nullopt, "scene key '" + key + "': " + why);
  }
  double number(const json& j, const std::string& key) const {
    if (!j.is_number() || !std::isfinite(j.get<double>())) fail(key, "expected a finite number");
    return j.get<double>();
  }
  Vec3d vec3(const json& j, const std::string& key) const {
    if (!j.is_array() || j.size() != 3) fail(key, "expected an array of 3 numbers");
    return {number(j[0], key), number(j[1], key), number(j[2], key)};
  }
  std::array<float, 3> color(const json& j, const std::string& key) const {
    const Vec3d v = vec3(j, key);
    if (v.x < 0 || v.y < 0 || v.z < 0) fail(key, "colors are not negative");
    return {float(v[0]), float(v[1]), float(v[2])};
  }
  bool boolean(const json& j, const std::string& key) const {
    if (!j.is_boolean()) fail(key, "expected true or false");
    return j.get<bool>();
  }
  void known(const json& object, const std::string& where,
             std::initializer_list<const char*> keys) const {
    if (!object.is_object()) fail(where, "expected an object");
    for (const auto& item : object.items()) {
      bool ok = false;
      for (const char* k : keys) ok = ok || item.key() == k;
      if (!ok) fail(where.empty() ? item.key() : where + "." + item.key(), "unknown key");
    }
  }
};

}  // namespace

BackFaces parseBackFaces(const std::string& text) {
  if (const std::optional<BackFaces> value = valueNamed(kBackFaceNames, text)) return *value;
  throw UsageError("back faces: '" + text + "' is not " + namesOf(kBackFaceNames));
}

Vec3d parseVec3(const std::string& text) {
  const auto v = parseNumbers(text, 3, "vector");
  return {v[0], v[1], v[2]};
}

LightSpec parseLight(const std::string& text) {
  const auto parts = split(text, ':');
  LightSpec light;
  if (parts.size() < 2) throw UsageError("light '" + text + "': expected KIND:X,Y,Z");
  size_t next = 2;
  if (parts[0] == "point") {
    light.position = parseVec3(parts[1]);
  } else if (parts[0] == "area") {
    if (parts.size() < 4) throw UsageError("light '" + text + "': an area light needs X,Y,Z:U:V");
    light.area = true;
    light.position = parseVec3(parts[1]);
    light.u = parseVec3(parts[2]);
    light.v = parseVec3(parts[3]);
    next = 4;
    if (parts.size() > next) {
      const double s = parseNumbers(parts[next++], 1, "light samples")[0];
      if (s < 1 || s > 1024 || s != std::floor(s))
        throw UsageError("light samples: expected a whole number from 1 to 1024");
      light.samples = int(s);
    }
  } else {
    throw UsageError("light '" + text + "': the kind is point or area");
  }
  if (parts.size() > next) {
    const Vec3d c = parseVec3(parts[next++]);
    light.color = {float(c[0]), float(c[1]), float(c[2])};
  }
  if (parts.size() > next) light.intensity = float(parseNumbers(parts[next++], 1, "intensity")[0]);
  if (parts.size() > next) throw UsageError("light '" + text + "': too many parts");
  return light;
}

namespace {

// A whole number from lo to hi.
int wholeNumber(const Fields& f, const json& j, const std::string& key, int lo, int hi) {
  const double v = f.number(j, key);
  if (v < lo || v > hi || v != std::floor(v))
    f.fail(key, fmt::format("a whole number from {} to {}", lo, hi));
  return int(v);
}

// The scene file's image-space points: layers, layer gap, opacity (one number, or one an input),
// shadow samples and eye-dome shading.
void readImage(const Fields& f, const json& j, ImageScene& image) {
  f.known(j, "image", {"layers", "layer_gap", "opacity", "shadow_samples", "eye_dome"});
  if (j.contains("layers"))
    image.layers = wholeNumber(f, j["layers"], "image.layers", 1, kMaxImageLayers);
  if (j.contains("layer_gap")) {
    image.layerGap = f.number(j["layer_gap"], "image.layer_gap");
    if (!(image.layerGap > 0)) f.fail("image.layer_gap", "a positive distance (world units)");
  }
  if (j.contains("opacity")) {
    const json& o = j["opacity"];
    image.opacity.clear();
    for (const json& v : o.is_array() ? o : json::array({o})) {
      const double a = f.number(v, "image.opacity");
      if (!(a > 0 && a <= 1)) f.fail("image.opacity", "each from 0 (excluded) to 1");
      image.opacity.push_back(float(a));
    }
  }
  if (j.contains("shadow_samples"))
    image.shadowSamples =
        wholeNumber(f, j["shadow_samples"], "image.shadow_samples", 1, kMaxImageShadowSamples);
  if (j.contains("eye_dome")) image.eyeDome = f.boolean(j["eye_dome"], "image.eye_dome");
}

// The scene file's "volume": a transfer function of up to 8 points, smoothing and step.
void readVolume(const Fields& f, const json& j, VolumeScene& volume) {
  f.known(j, "volume", {"transfer", "smoothing", "step"});
  if (j.contains("transfer")) {
    const json& t = j["transfer"];
    if (!t.is_array() || t.empty() || t.size() > 8)
      f.fail("volume.transfer", "1 to 8 points [value, r, g, b, extinction]");
    volume.transfer.clear();
    for (const json& point : t) {
      if (!point.is_array() || point.size() != 5)
        f.fail("volume.transfer", "each point [value, r, g, b, extinction]");
      std::array<float, 5> v{};
      for (size_t k = 0; k < 5; ++k) v[k] = float(f.number(point[k], "volume.transfer"));
      if (v[1] < 0 || v[2] < 0 || v[3] < 0 || v[4] < 0)
        f.fail("volume.transfer", "colors and extinctions are not negative");
      if (!volume.transfer.empty() && v[0] < volume.transfer.back()[0])
        f.fail("volume.transfer", "points by increasing value");
      volume.transfer.push_back(v);
    }
  }
  for (const char* key : {"smoothing", "step"})
    if (j.contains(key)) {
      const double v = f.number(j[key], std::string("volume.") + key);
      if (!(v > 0)) f.fail(std::string("volume.") + key, "a positive distance (world units)");
      (std::string(key) == "smoothing" ? volume.smoothing : volume.step) = v;
    }
}

// The scene file's camera: eye and target, up and fov optional.
void readCamera(const Fields& f, const json& c, Scene& scene) {
  f.known(c, "camera", {"eye", "target", "up", "fov"});
  Camera cam = scene.camera.value_or(Camera{});
  if (!c.contains("eye") || !c.contains("target")) f.fail("camera", "needs eye and target");
  cam.eye = f.vec3(c["eye"], "camera.eye");
  cam.target = f.vec3(c["target"], "camera.target");
  if (c.contains("up")) cam.up = f.vec3(c["up"], "camera.up");
  if (c.contains("fov")) cam.fovDegrees = f.number(c["fov"], "camera.fov");
  if (!(cam.fovDegrees > 1 && cam.fovDegrees < 179)) f.fail("camera.fov", "from 1 to 179");
  scene.camera = cam;
}

// The scene file's lights, which replace the scene's.
void readLights(const Fields& f, const json& lights, Scene& scene) {
  if (!lights.is_array()) f.fail("lights", "expected an array");
  scene.lights.clear();
  for (const json& l : lights) {
    f.known(l, "lights[]",
            {"type", "position", "u", "v", "color", "intensity", "samples", "falloff"});
    LightSpec light;
    const std::string type = l.value("type", "point");
    if (type != "point" && type != "area") f.fail("lights[].type", "point or area");
    light.area = type == "area";
    if (!l.contains("position")) f.fail("lights[].position", "missing");
    light.position = f.vec3(l["position"], "lights[].position");
    if (light.area) {
      if (!l.contains("u") || !l.contains("v")) f.fail("lights[]", "an area light needs u, v");
      light.u = f.vec3(l["u"], "lights[].u");
      light.v = f.vec3(l["v"], "lights[].v");
    }
    if (l.contains("color")) light.color = f.color(l["color"], "lights[].color");
    if (l.contains("intensity"))
      light.intensity = float(f.number(l["intensity"], "lights[].intensity"));
    if (l.contains("falloff")) {
      if (!l["falloff"].is_string() ||
          (l["falloff"] != "none" && l["falloff"] != "inverse_square"))
        f.fail("lights[].falloff", "none or inverse_square");
      light.inverseSquare = l["falloff"] == "inverse_square";
    }
    if (l.contains("samples")) {
      const double s = f.number(l["samples"], "lights[].samples");
      if (s < 1 || s > 1024 || s != std::floor(s)) f.fail("lights[].samples", "1 to 1024");
      light.samples = int(s);
    }
    scene.lights.push_back(light);
  }
  if (scene.lights.size() > gpu::kMaxLights)
    f.fail("lights", "at most " + std::to_string(gpu::kMaxLights) + " lights");
}

// The scene file's material: what it names replaces the scene's.
void readMaterial(const Fields& f, const json& m, Material& mat) {
  f.known(m, "material",
          {"color", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior",
           "absorption"});
  if (m.contains("color")) mat.color = f.color(m["color"], "material.color");
  auto unit = [&](const char* key, float& out) {
    if (!m.contains(key)) return;
    const double v = f.number(m[key], std::string("material.") + key);
    if (v < 0 || v > 1) f.fail(std::string("material.") + key, "from 0 to 1");
    out = float(v);
  };
  unit("diffuse", mat.diffuse);
  unit("specular", mat.specular);
  unit("reflectivity", mat.reflectivity);
  unit("transparency", mat.transparency);
  if (m.contains("shininess"))
    mat.shininess = float(f.number(m["shininess"], "material.shininess"));
  if (m.contains("ior")) {
    mat.ior = float(f.number(m["ior"], "material.ior"));
    if (!(mat.ior >= 1.0f && mat.ior <= 4.0f)) f.fail("material.ior", "from 1 to 4");
  }
  if (m.contains("absorption")) mat.absorption = f.color(m["absorption"], "material.absorption");
  if (mat.reflectivity + mat.transparency > 1.0f)
    f.fail("material", "reflectivity + transparency is at most 1");
}

// The scene file's light environment and rendering switches.
void readRendering(const Fields& f, const json& j, const std::filesystem::path& path,
                   Scene& scene) {
  if (j.contains("ambient")) scene.ambient = f.color(j["ambient"], "ambient");
  if (j.contains("sky_top")) scene.skyTop = f.color(j["sky_top"], "sky_top");
  if (j.contains("sky_bottom")) scene.skyBottom = f.color(j["sky_bottom"], "sky_bottom");
  if (j.contains("up")) scene.up = f.vec3(j["up"], "up");
  if (j.contains("environment")) {
    if (!j["environment"].is_string()) f.fail("environment", "expected a file name");
    const std::filesystem::path env = j["environment"].get<std::string>();
    scene.environment = (env.is_relative() ? path.parent_path() / env : env).string();
  }
  if (j.contains("environment_intensity"))
    scene.environmentIntensity =
        float(f.number(j["environment_intensity"], "environment_intensity"));
  if (j.contains("shadows")) scene.shadows = f.boolean(j["shadows"], "shadows");
  if (j.contains("reflections")) scene.reflections = f.boolean(j["reflections"], "reflections");
  if (j.contains("refractions")) scene.refractions = f.boolean(j["refractions"], "refractions");
  if (j.contains("bounces")) {
    const double b = f.number(j["bounces"], "bounces");
    if (b < 0 || b > 8 || b != std::floor(b)) f.fail("bounces", "a whole number from 0 to 8");
    scene.bounces = int(b);
  }
  if (j.contains("samples")) {
    const double s = f.number(j["samples"], "samples");
    if (s < 1 || s > 256 || s != std::floor(s)) f.fail("samples", "a whole number from 1 to 256");
    scene.samples = int(s);
  }
  if (j.contains("lod_pixels")) {
    scene.lodPixels = float(f.number(j["lod_pixels"], "lod_pixels"));
    if (!(scene.lodPixels >= 0)) f.fail("lod_pixels", "not negative");
  }
  if (j.contains("backfaces")) {
    const std::optional<BackFaces> value =
        j["backfaces"].is_string() ? valueNamed(kBackFaceNames, j["backfaces"].get<std::string>())
                                   : std::nullopt;
    if (!value) f.fail("backfaces", namesOf(kBackFaceNames));
    scene.backFaces = *value;
  }
  if (j.contains("backface_tint")) scene.backTint = f.color(j["backface_tint"], "backface_tint");
  if (j.contains("ground")) {
    // true: under the surface (completeScene places it); a number: its height along up.
    const nlohmann::json& g = j["ground"];
    if (g.is_boolean()) {
      scene.groundHeight.reset();
      scene.groundAuto = g.get<bool>();
    } else {
      scene.groundHeight = f.number(g, "ground");
      scene.groundAuto = false;
    }
  }
  if (j.contains("ground_color")) scene.groundColor = f.color(j["ground_color"], "ground_color");
  if (j.contains("caustics")) {
    const double n = f.number(j["caustics"], "caustics");
    if (n < 0 || n > kMaxCausticPhotons || n != std::floor(n))
      f.fail("caustics", fmt::format("a whole number of photons from 0 to {}", kMaxCausticPhotons));
    scene.caustics = uint32_t(n);
  }
  if (j.contains("lighting")) {
    const std::optional<Lighting> value =
        j["lighting"].is_string() ? valueNamed(kLightingNames, j["lighting"].get<std::string>())
                                  : std::nullopt;
    if (!value) f.fail("lighting", namesOf(kLightingNames));
    scene.lighting = *value;
  }
  if (j.contains("draw")) {
    const std::optional<Draw> value =
        j["draw"].is_string() ? valueNamed(kDrawNames, j["draw"].get<std::string>()) : std::nullopt;
    if (!value) f.fail("draw", namesOf(kDrawNames));
    scene.draw = *value;
  }
}

}  // namespace

void loadScene(const std::filesystem::path& path, Scene& scene) {
  const std::string file = path.string();
  std::ifstream in(path);
  if (!in) throw FileError(file, std::nullopt, "cannot open the scene file");
  json j = json::parse(in, nullptr, false);
  if (j.is_discarded()) throw FileError(file, std::nullopt, "not valid JSON");
  const Fields f{file};
  f.known(j, "",
          {"camera", "lights", "material", "ambient", "sky_top", "sky_bottom", "up", "environment",
           "environment_intensity", "shadows", "reflections", "refractions", "bounces", "samples",
           "lod_pixels", "backfaces", "backface_tint", "lighting", "draw", "ground", "ground_color",
           "caustics", "image", "volume"});
  if (j.contains("camera")) readCamera(f, j["camera"], scene);
  if (j.contains("lights")) readLights(f, j["lights"], scene);
  if (j.contains("material")) readMaterial(f, j["material"], scene.material);
  readRendering(f, j, path, scene);
  if (j.contains("image")) readImage(f, j["image"], scene.image);
  if (j.contains("volume")) readVolume(f, j["volume"], scene.volume);
}

namespace {

// A view direction (from the surface towards the eye) and what is seen from it.
struct CandidateView {
  Vec3d from{};
  size_t seen = 0;  // cells nearest the eye in at least one grid pixel
  std::vector<uint32_t> seenCells;
};

// The cells seen looking along -from, orthographically: nearest the eye in at least one pixel of
// a grid over their extent whose pixels are `pixel` wide (at most kMaxGrid of them a side).
CandidateView seenFrom(const std::vector<SurfaceCell>& cells, const Vec3d& from, const Vec3d& up,
                       double pixel) {
  constexpr int kMaxGrid = 1024;
  const Vec3d right = glm::normalize(glm::cross(-from, up)), top = glm::cross(right, -from);
  double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
  for (const SurfaceCell& c : cells) {
    const double x = glm::dot(c.center, right), y = glm::dot(c.center, top);
    lo[0] = std::min(lo[0], x - c.size / 2), hi[0] = std::max(hi[0], x + c.size / 2);
    lo[1] = std::min(lo[1], y - c.size / 2), hi[1] = std::max(hi[1], y + c.size / 2);
  }
  pixel = std::max(pixel, std::max({hi[0] - lo[0], hi[1] - lo[1], 1e-300}) / kMaxGrid);
  const int grid =
      std::clamp(int(std::ceil(std::max(hi[0] - lo[0], hi[1] - lo[1]) / pixel)), 1, kMaxGrid);
  std::vector<double> depth(size_t(grid) * grid, -INFINITY);
  std::vector<uint32_t> nearest(size_t(grid) * grid, UINT32_MAX);
  const auto cellOf = [&](double v, int axis) {
    return std::clamp(int(std::floor((v - lo[axis]) / pixel)), 0, grid - 1);
  };
  for (uint32_t i = 0; i < cells.size(); ++i) {
    const SurfaceCell& c = cells[i];
    const double x = glm::dot(c.center, right), y = glm::dot(c.center, top);
    const double z = glm::dot(c.center, from);  // larger: nearer the eye
    for (int py = cellOf(y - c.size / 2, 1); py <= cellOf(y + c.size / 2, 1); ++py)
      for (int px = cellOf(x - c.size / 2, 0); px <= cellOf(x + c.size / 2, 0); ++px)
        if (const size_t at = size_t(py) * grid + px; z > depth[at]) {
          depth[at] = z;
          nearest[at] = i;
        }
  }
  CandidateView view{.from = from};
  std::vector<bool> seen(cells.size(), false);
  for (const uint32_t i : nearest)
    if (i != UINT32_MAX && !seen[i]) {
      seen[i] = true;
      view.seenCells.push_back(i);
    }
  view.seen = view.seenCells.size();
  return view;
}

}  // namespace

Camera defaultCamera(const std::vector<SurfaceCell>& cells, const Vec3d& up, double fovDegrees,
                     double aspect) {
  if (cells.empty()) throw UsageError("nothing to frame: no surface and no points");
  const Vec3d u = normalized(up);
  // The front: a horizontal direction not along up; vertical views lean 20 degrees towards it.
  Vec3d front = std::abs(u[2]) < 0.9 ? Vec3d{0, 0, 1} : Vec3d{0, -1, 0};
  front = normalized(front - u * glm::dot(front, u));
  // Pixels as wide as the median cell: a view that sees the surface at a slant sees fewer cells.
  std::vector<double> sizes;
  for (const SurfaceCell& c : cells) sizes.push_back(c.size);
  std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
  const double pixel = sizes[sizes.size() / 2];
  std::optional<CandidateView> best;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j)
      for (int k = -1; k <= 1; ++k) {
        if (i == 0 && j == 0 && k == 0) continue;
        Vec3d from = glm::normalize(Vec3d(i, j, k));
        if (const double along = glm::dot(from, u); std::abs(along) > 0.99) {
          const double tilt = 20.0 * M_PI / 180.0;
          from = (along > 0 ? u : -u) * std::cos(tilt) + front * std::sin(tilt);
        }
        if (glm::dot(from, u) < -1e-9) continue;  // below the horizon: the ground, the underside
        CandidateView view = seenFrom(cells, from, u, pixel);
        if (!best || view.seen > best->seen ||
            (view.seen == best->seen && glm::dot(from, u) > glm::dot(best->from, u)))
          best = std::move(view);
      }

  // The seen cells' box across the view and along it; the target at its center.
  const Vec3d from = best->from, forward = -from;
  const Vec3d right = glm::normalize(glm::cross(forward, u)), top = glm::cross(right, forward);
  Vec3d lo(INFINITY), hi(-INFINITY);
  std::vector<Vec3d> seen;
  for (const uint32_t i : best->seenCells) {
    const Vec3d& c = cells[i].center;
    const Vec3d p(glm::dot(c, right), glm::dot(c, top), glm::dot(c, from));
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
    seen.push_back(c);
  }
  const Vec3d mid = (lo + hi) * 0.5;
  const Vec3d target = right * mid[0] + top * mid[1] + from * mid[2];
  // The distance at which the seen cell farthest from the picture's center reaches 80 % of the
  // half-width or half-height: bisection, the fill falling as the eye moves away.
  const double tanHalf = std::tan(fovDegrees * M_PI / 360.0);
  const auto fill = [&](double distance) -> double {
    const Vec3d eye = target + from * distance;
    double most = 0.0;
    for (const Vec3d& p : seen) {
      const Vec3d d = p - eye;
      const double z = glm::dot(d, forward);
      if (z <= 0.0) return INFINITY;  // behind the eye: far too close
      most = std::max({most, std::abs(glm::dot(d, right)) / (z * tanHalf * aspect),
                       std::abs(glm::dot(d, top)) / (z * tanHalf)});
    }
    return most;
  };
  double nearD = 1e-9 * std::max(glm::length(hi - lo), 1e-300), farD = nearD;
  while (fill(farD) > 0.8) farD *= 2.0;
  for (int step = 0; step < 60; ++step) {
    const double d = std::sqrt(nearD * farD);
    (fill(d) > 0.8 ? nearD : farD) = d;
  }
  return {target + from * farD, target, u, fovDegrees};
}

LightSpec defaultLight(const Camera& c, const Bounds& b) {
  const Vec3d forward = normalized(c.target - c.eye);
  const Vec3d right = normalized(glm::cross(forward, c.up));
  const Vec3d up = glm::cross(right, forward);
  const double radius = 0.5 * glm::length(b.hi - b.lo);
  LightSpec light;
  light.position = c.target + (right * -0.6 + up + forward * -0.7) * (3.0 * radius);
  return light;
}

bool refractionRays(const gpu::FrameParams& p) {
  return p.options.y > 0u && (p.options.x & gpu::kOptionRefractions) != 0u && p.material.w > 0.0f;
}

bool secondaryRays(const gpu::FrameParams& p) {
  const bool mirrors =
      p.options.y > 0u && (p.options.x & gpu::kOptionReflections) != 0u && p.material.z > 0.0f;
  return mirrors || refractionRays(p);
}

namespace {

constexpr double kShadowStartCells = 2.0;  // see frameParams

// The caustics of a frame whose ground is set (p.ground, frame units): the disc photons aim at
// (the sphere around the content box, seen from each light), and the map: a square on the ground
// centered under the content's center, reaching 1.5 content radii plus twice the center's height
// above the ground from it (where lights well above the horizon focus what passes through).
void setCaustics(gpu::FrameParams& p, const Scene& scene, const FrameSetup& s) {
  const glm::dvec3 lo(s.contentLo), hi(s.contentHi);
  const glm::dvec3 center = 0.5 * (lo + hi);
  const double radius = 0.5 * glm::length(hi - lo);
  const glm::dvec3 n(p.ground.x, p.ground.y, p.ground.z);
  const double height = glm::dot(n, center) - double(p.ground.w);
  const glm::dvec3 under = center - height * n;
  const double half = 1.5 * radius + 2.0 * std::max(height, 0.0);
  const double cell = 2.0 * half / gpu::kCausticCells;
  const glm::dvec3 a = std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  const glm::dvec3 e1 = glm::normalize(glm::cross(n, a)), e2 = glm::cross(n, e1);
  const auto lights = uint32_t(std::min<size_t>(scene.lights.size(), gpu::kMaxLights));
  p.caustics = glm::uvec4(scene.caustics, scene.caustics * lights, 0, 0);
  p.causticDisc = glm::vec4(glm::vec3(center), float(radius));
  const double middle = 0.5 * gpu::kCausticCells;
  p.causticU = glm::vec4(glm::vec3(e1 / cell), float(middle - glm::dot(e1, under) / cell));
  p.causticV = glm::vec4(glm::vec3(e2 / cell), float(middle - glm::dot(e2, under) / cell));
}

}  // namespace

gpu::FrameParams frameParams(const Scene& scene, const Frame& frame, uint8_t maxLevel,
                             const FrameSetup& s) {
  using glm::vec4;
  ISO_CHECK(scene.camera.has_value());
  const Camera& c = *scene.camera;
  const auto toFrame = [&](const Vec3d& p) {
    return vec4(float((p[0] - frame.origin[0]) / frame.size),
                float((p[1] - frame.origin[1]) / frame.size),
                float((p[2] - frame.origin[2]) / frame.size), 0.0f);
  };
  const auto toFrameVector = [&](const Vec3d& v) {
    return vec4(float(v[0] / frame.size), float(v[1] / frame.size), float(v[2] / frame.size), 0);
  };
  const auto rgb = [](const std::array<float, 3>& a, float w = 0.0f) {
    return vec4(a[0], a[1], a[2], w);
  };
  gpu::FrameParams p{};
  const Vec3d forward = normalized(c.target - c.eye);
  const Vec3d right = normalized(glm::cross(forward, c.up));
  const Vec3d up = glm::cross(right, forward);
  const double tanHalf = std::tan(c.fovDegrees * M_PI / 360.0);
  const double aspect = double(s.width) / double(std::max(s.height, 1u));
  p.eye = toFrame(c.eye);
  p.eye.w = float(2.0 * tanHalf / std::max(s.height, 1u));
  p.right = vec4(float(right[0] * tanHalf * aspect), float(right[1] * tanHalf * aspect),
                 float(right[2] * tanHalf * aspect), 0);
  p.up = vec4(float(up[0] * tanHalf), float(up[1] * tanHalf), float(up[2] * tanHalf), 0);
  p.forward = vec4(float(forward[0]), float(forward[1]), float(forward[2]), 0);
  p.image = {s.width, s.height, uint32_t(std::max(scene.samples, 1)), s.frameNumber};
  uint32_t options = 0;
  if (scene.shadows) options |= gpu::kOptionShadows;
  if (scene.reflections) options |= gpu::kOptionReflections;
  if (scene.refractions) options |= gpu::kOptionRefractions;
  options |= recordOptionBits(s.blob);
  if (s.swapRedBlue) options |= gpu::kOptionSwapRB;
  if (s.environmentWidth > 0) options |= gpu::kOptionEnvironment;
  if (s.requests) options |= gpu::kOptionRequests;
  if (s.flatTraversal) options |= gpu::kOptionFlatTraversal;
  const bool splats = scene.draw != Draw::Surface && s.splatIndex != kNoParent;
  const bool ground = scene.groundHeight.has_value();
  // (Tile cones see the surface's nodes, not the splats, a point set surface or the ground.)
  if (s.tileCones && !splats && !ground && !s.pss) options |= gpu::kOptionTileCones;
  if (s.pss) options |= gpu::kOptionPss;
  if (ground) options |= gpu::kOptionGround;
  if (splats) options |= gpu::kOptionSplats;
  if (splats && scene.draw == Draw::Points) options |= gpu::kOptionNoSurface;
  if (scene.backFaces == BackFaces::Tint) options |= gpu::kOptionBackTint;
  if (scene.backFaces == BackFaces::Hide) options |= gpu::kOptionBackHide;
  if (s.blob.irradiance && scene.lighting != Lighting::Live)
    options |= gpu::kOptionBakedLight |
               (scene.lighting == Lighting::Both ? gpu::kOptionLiveLight : 0u);
  p.options = {options, uint32_t(std::max(scene.bounces, 0)), s.topChunk, s.chunkCount};
  p.pool = {s.poolWordsLog2, s.poolWords, s.environmentWidth, s.environmentHeight};
  setColorTable(p);
  // Rays leave surfaces a hundredth of the finest cell away (the side flag does the rest), and
  // shadow rays count blockers from two finest cells on: where the corner fit bends a leaf's
  // zero set against its stored normals, a light just above the shading normal's horizon lies
  // below the patch's own, and its shadow ray met the patch it left (dark blotches on the demo
  // kitten without the start, a few at one cell, none at two; specs/viewer.md, "Shadows").
  const double finest = std::ldexp(1.0, -int(maxLevel));
  p.lod = vec4(scene.lodPixels, float(0.01 * finest), scene.environmentIntensity,
               float(kShadowStartCells * finest));
  p.ambient = rgb(scene.ambient);
  p.albedo = rgb(scene.material.color, scene.material.shininess);
  p.material = vec4(scene.material.diffuse, scene.material.specular, scene.material.reflectivity,
                    scene.material.transparency);
  p.medium = vec4(scene.material.ior, float(scene.material.absorption[0] * frame.size),
                  float(scene.material.absorption[1] * frame.size),
                  float(scene.material.absorption[2] * frame.size));
  p.skyTop = rgb(scene.skyTop);
  p.skyBottom = rgb(scene.skyBottom);
  const Vec3d worldUp = normalized(scene.up.value_or(c.up));
  p.worldUp = vec4(float(worldUp[0]), float(worldUp[1]), float(worldUp[2]), 0);
  if (ground) {
    // dot(up, world) = height, with world = origin + size · u: dot(up, u) = (height -
    // dot(up, origin)) / size.
    const Vec3d origin(frame.origin[0], frame.origin[1], frame.origin[2]);
    p.ground = vec4(float(worldUp[0]), float(worldUp[1]), float(worldUp[2]),
                    float((*scene.groundHeight - glm::dot(worldUp, origin)) / frame.size));
    p.groundColor = rgb(scene.groundColor);
    if (scene.caustics > 0) setCaustics(p, scene, s);
  }
  p.backface = rgb(scene.backTint);
  p.surface = vec4(s.blob.distanceUnit, 0, 0, 0);
  p.contentLo = vec4(s.contentLo, 0);
  p.contentHi = vec4(s.contentHi, 0);
  if (splats) {
    p.splatIndex = glm::uvec4(s.splatIndex, 0, 0, 0);
    p.splat = vec4(kSplatBlendWindow, 0, 0, 0);
    // Secondary rays leave a blend of disks half a typical radius away: the neighbouring disks
    // of a curved or noisy scan lie that far off its tangent plane.
    p.lod.y = std::max(p.lod.y, 0.5f * s.splatRadius);
  }
  for (size_t i = 0; i < scene.lights.size() && i < gpu::kMaxLights; ++i) {
    const LightSpec& l = scene.lights[i];
    gpu::Light& g = p.lights[i];
    g.position = toFrame(l.position);
    g.position.w = float(l.area ? gpu::kLightArea : gpu::kLightPoint);
    g.color = vec4(l.color[0] * l.intensity, l.color[1] * l.intensity, l.color[2] * l.intensity,
                   float(l.samples));
    g.u = toFrameVector(l.u);
    g.v = toFrameVector(l.v);
    if (l.inverseSquare) {
      // The shader divides by r² in frame units: r_world² = r² · size².
      const float scale = float(1.0 / (frame.size * frame.size));
      g.color = vec4(glm::vec3(g.color) * scale, g.color.w);
      g.u.w = 1.0f;
    }
  }
  return p;
}

}  // namespace iso::viewer
