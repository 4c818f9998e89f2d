// `iso view FILE`: look at an .iso file in a window, or render it to a picture (--headless, --cpu)
// or a benchmark (--bench), streaming its chunks under a GPU memory budget (specs/viewer.md).
#include <fmt/core.h>

#include <atomic>
#include <fstream>
#include <sstream>
#include <thread>

#include "iso/error.h"
#include "iso/points.h"
#include "iso/reader.h"
#include "pipeline/base/files.h"
#include "base/image.h"
#include "pipeline/output/keep_points.h"
#include "tools/iso/inputs.h"
#include "tools/iso/commands.h"
#include "tools/iso/interrupt.h"
#include "tools/iso/text.h"
#include "tools/iso/view_points.h"
#include "viewer/point_image_gpu.h"
#include "viewer/renderer.h"
#include "viewer/view.h"

namespace iso::cli {
namespace {

struct ViewArgs {
  viewer::ViewOptions view;
  bool headless = false, cpu = false, bench = false;
  std::string vram = "1G", upload = "16M", camera, up, color, ambient, environment, backFaces;
  std::string lighting;
  double fov = 0;
  std::vector<std::string> lights;
  std::optional<float> reflectivity, transparency, shininess, environmentIntensity, lodPixels;
  std::string ior;  // one index, or three (R, G, B: --draw pss)
  std::string pss = "fast";
  bool drawPss = false;  // --draw pss (cleared from `draw` before the scene is built)
  std::string volumePoints, volume;  // --draw pss: scattered values inside the surface
  std::string withPss;               // --with-pss: a point set surface beside an .iso's surface
  std::optional<int> bounces, samples;
  bool noShadows = false, noReflections = false, noRefractions = false;
  bool points = false, ground = false;
  std::optional<double> groundHeight;
  std::optional<uint32_t> caustics;
  std::string draw;
  std::string traversal = "nested";
  // Image-space points (--draw image; the default for raw scans).
  std::vector<std::string> files;
  viewer::ImageViewOptions image;
  std::string antialias = "silhouettes", opacity;
  std::optional<int> layers, shadowSamples;
  std::optional<double> layerGap;
  bool noSmooth = false, eyeDome = false;
};

// The image-space settings of the command line (the rest come from the scene).
void setImageOptions(ViewArgs& a) {
  viewer::ImageSettings& s = a.image.settings;
  s.antialias = a.antialias == "off"     ? viewer::ImageAntialias::Off
                : a.antialias == "edges" ? viewer::ImageAntialias::Edges
                                         : viewer::ImageAntialias::Silhouettes;
  s.smooth = !a.noSmooth;
  s.shadows = true;  // unless --no-shadows (the scene's)
}

// The points read, in the scene's material color where they have none.
void colorPoints(const ViewArgs& a, viewer::ImageInputs& inputs) {
  if (a.view.scene.material.color != viewer::Material{}.color)
    for (auto& o : inputs.objects)
      if (o.colors.empty())
        o.color = glm::vec3(a.view.scene.material.color[0], a.view.scene.material.color[1],
                            a.view.scene.material.color[2]);
}

// The most points --vram holds beside the picture.
uint64_t imagePointBudget(const ViewArgs& a) {
  const size_t lights = std::max<size_t>(a.view.scene.lights.size(), 1);
  return viewer::imageBudget(a.view.vram, UINT64_MAX, a.view.width, a.view.height, lights).points;
}

// The tracer window's image-space mode (key K): the .iso file's kept points, read when asked.
viewer::WindowImageMode windowImageMode(ViewArgs& a) {
  setImageOptions(a);
  viewer::WindowImageMode mode;
  mode.options = std::make_shared<viewer::ImageViewOptions>(a.image);
  mode.read = [&a] {
    ImageFiles files = openImageFiles({a.view.file}, imagePointBudget(a));
    auto inputs = std::make_shared<viewer::ImageInputs>(readImageInputs(files));
    colorPoints(a, *inputs);
    return std::shared_ptr<const viewer::ImageInputs>(std::move(inputs));
  };
  return mode;
}

// Raw scans, or --draw image: the point files read and drawn as image-space points (beyond
// what fits --vram, those the view needs); the window opens at once, draws what is read so far,
// and once all is read asks for the points of each view the camera rests at.
int viewImage(ViewArgs& a) {
  setImageOptions(a);
  const auto& opacity = a.view.scene.image.opacity;
  if (opacity.size() > 1 && opacity.size() != a.files.size())
    throw UsageError(fmt::format("--opacity: one number, or one for each of the {} files",
                                 a.files.size()));
  ImageLoad load;
  load.maxPoints = imagePointBudget(a);
  ImageFiles files = openImageFiles({a.files.begin(), a.files.end()}, load.hostPoints);
  const auto finish = [&](viewer::ImageInputs& inputs) { colorPoints(a, inputs); };
  // The points for the scene's camera (framed on them when it has none).
  const auto forCamera = [&](const ImagePoints& points, const viewer::Camera& camera,
                             uint32_t width, uint32_t height) {
    const PointView view = pointViewOf(camera, width, height);
    viewer::ImageInputs inputs = imageInputs(points, load.maxPoints, &view);
    finish(inputs);
    return inputs;
  };
  if (!a.cpu && !a.headless && !a.bench) {
    // The window: reading goes on beside it, previews first.
    viewer::ImageFeed feed;
    std::atomic<bool> stop = false;
    load.preview = [&](viewer::ImageInputs&& preview) {
      finish(preview);
      feed.publish(std::move(preview));
    };
    load.stop = &stop;
    std::thread reader([&] {
      try {
        const ImagePoints points = readImagePoints(files, load);
        if (stop) return;
        const viewer::Camera framed =
            viewer::sceneCamera(a.view.scene, points.frame, viewer::aspectOf(a.view));
        feed.publish(forCamera(points, framed, a.view.width, a.view.height));
        if (points.store.size() <= load.maxPoints) return;  // all of them drawn
        while (!stop)
          if (const auto view = feed.wanted(std::chrono::milliseconds(50)))
            feed.publish(forCamera(points, view->camera, view->width, view->height));
      } catch (...) {
        feed.fail(std::current_exception());
      }
    });
    int code = 0;
    try {
      code = viewer::viewImageWindow(a.view, a.image, feed);
    } catch (...) {
      stop = true;
      reader.join();
      throw;
    }
    stop = true;
    reader.join();
    return code;
  }
  const ImagePoints points = readImagePoints(files, load);
  if (a.bench) {  // an orbit: the same points from every side
    viewer::ImageInputs inputs = imageInputs(points, load.maxPoints);
    finish(inputs);
    return viewer::viewImageBench(a.view, a.image, inputs);
  }
  // Chosen once: the drivers draw from the camera the points were chosen for.
  a.view.scene.camera = viewer::sceneCamera(a.view.scene, points.frame, viewer::aspectOf(a.view));
  const viewer::ImageInputs inputs =
      forCamera(points, *a.view.scene.camera, a.view.width, a.view.height);
  if (a.cpu) return viewer::viewImageCpu(a.view, a.image, inputs);
  return viewer::viewImageHeadless(a.view, a.image, inputs);
}

// --ior: one index, or three (R, G, B) for --draw pss; each in [1, 4].
std::vector<double> parseIors(const ViewArgs& a) {
  const size_t count = std::count(a.ior.begin(), a.ior.end(), ',') + 1;
  if (count != 1 && count != 3)
    throw UsageError("--ior: one index of refraction, or three (R,G,B), not '" + a.ior + "'");
  if (count == 3 && !a.drawPss)
    throw UsageError("--ior R,G,B (one index a channel) goes with --draw pss");
  const std::vector<double> iors = viewer::parseNumbers(a.ior, count, "--ior");
  for (double v : iors)
    if (!(v >= 1.0 && v <= 4.0)) throw UsageError("--ior: each index within 1 to 4");
  return iors;
}

// --volume-points FILE [--volume NAME]: the file's points and the scalar NAME of each (a PLY or
// PCD property, a named text column, LAS/LAZ intensity, classification, ...); without --volume,
// its one scalar. Without --volume-points, --volume NAME: the volume points an .iso input keeps
// with values NAME (iso convert --volume-points).
void readVolumePoints(const ViewArgs& a, viewer::PssViewOptions& pss) {
  if (a.volumePoints.empty()) {
    std::string all;
    for (const std::string& file : a.files) {
      if (std::filesystem::path(file).extension() != ".iso" && !isIsoFile(file)) continue;
      const Reader reader = Reader::open(file);
      const std::vector<std::string> names = keptValueNames(reader, kVolumePointsKind);
      for (const std::string& n : names) all += (all.empty() ? "" : ", ") + n;
      if (std::find(names.begin(), names.end(), a.volume) == names.end()) continue;
      forEachKeptPoints(
          reader,
          [&](const PointCloud& points) {
            pss.volumePositions.insert(pss.volumePositions.end(), points.positions.begin(),
                                       points.positions.end());
            for (double v : points.extras) pss.volumeValues.push_back(float(v));
          },
          a.volume, kVolumePointsKind);
    }
    if (pss.volumePositions.empty())
      throw UsageError("--volume " + a.volume + ": no .iso input keeps volume points of that " +
                       "value (" + (all.empty() ? "they keep none" : "they keep: " + all) +
                       "); give a point file of them with --volume-points");
    return;
  }
  ReadOptions options;
  options.keepExtras = true;
  const std::unique_ptr<PointReader> reader = openPointFile(a.volumePoints, options);
  const auto& names = reader->info().extraNames;
  if (names.empty())
    throw FileError(a.volumePoints, std::nullopt,
                    "has no scalar for a volume (a PLY or PCD property, a named text column, or "
                    "LAS intensity)");
  std::string all;
  for (const std::string& n : names) all += (all.empty() ? "" : ", ") + n;
  if (a.volume.empty() && names.size() > 1)
    throw UsageError("--volume-points " + a.volumePoints + " has several scalars (" + all +
                     "): name one with --volume");
  const size_t k = a.volume.empty() ? 0 : extraIndex(reader->info(), a.volume);
  PointCloud batch;
  while (reader->read(batch, 1u << 20) > 0) {
    for (size_t i = 0; i < batch.size(); ++i) {
      pss.volumePositions.push_back(batch.positions[i]);
      pss.volumeValues.push_back(float(batch.extras[i * names.size() + k]));
    }
    batch.clear();
  }
}

// --draw pss: the points (an .iso file's kept points, or point files) as a point set surface,
// all of them, ray traced on the CPU reference, the GPU, or timed.
int viewPss(ViewArgs& a) {
  viewer::PssViewOptions pss;
  pss.exact = a.pss == "exact";
  if (!a.ior.empty()) {
    const std::vector<double> iors = parseIors(a);
    pss.iors = iors.size() == 3 ? glm::vec3(iors[0], iors[1], iors[2]) : glm::vec3(iors[0]);
  } else {
    pss.iors = glm::vec3(a.view.scene.material.ior);
  }
  if (!a.volume.empty() || !a.volumePoints.empty()) readVolumePoints(a, pss);
  ImageFiles files = openImageFiles({a.files.begin(), a.files.end()}, hostPointBudget());
  viewer::ImageInputs inputs = imageInputs(readImagePoints(files), UINT64_MAX);
  colorPoints(a, inputs);
  if (a.cpu) return viewer::viewPssCpu(a.view, pss, inputs);
  if (a.headless) return viewer::viewPssHeadless(a.view, pss, inputs);
  if (a.bench) return viewer::viewPssBench(a.view, pss, inputs);
  return viewer::viewPssWindow(a.view, pss, inputs);
}

// --with-pss POINTS: the points (a point file, or an .iso file's kept points) as a point set
// surface in the .iso file's scene, in its frame units, with the volume of --volume-points or
// --volume inside it.
void withPss(ViewArgs& a) {
  viewer::PssViewOptions pss;
  pss.exact = a.pss == "exact";
  // --volume NAME alone reads the volume points of the --with-pss file when it is an .iso.
  ViewArgs volume = a;
  volume.files = {a.withPss};
  if (!a.volume.empty() || !a.volumePoints.empty()) readVolumePoints(volume, pss);
  ImageFiles files = openImageFiles({a.withPss}, hostPointBudget());
  viewer::ImageInputs inputs = imageInputs(readImagePoints(files), UINT64_MAX);
  const Reader reader = Reader::open(a.view.file);
  a.view.pss = viewer::pssObject(inputs, pss, a.view.scene, reader.header().frame);
}

viewer::Vec3d parseUp(const std::string& text) {
  if (text == "x") return {1, 0, 0};
  if (text == "y") return {0, 1, 0};
  if (text == "z") return {0, 0, 1};
  if (text == "-x") return {-1, 0, 0};
  if (text == "-y") return {0, -1, 0};
  if (text == "-z") return {0, 0, -1};
  return viewer::parseVec3(text);
}

// The scene: defaults, then the scene file, then the command line.
void buildScene(ViewArgs& a) {
  viewer::Scene& s = a.view.scene;
  if (!a.view.sceneFile.empty()) viewer::loadScene(a.view.sceneFile, s);
  if (!a.camera.empty()) {
    const std::vector<double> v = viewer::parseNumbers(a.camera, 9, "--camera eye,target,up");
    viewer::Camera c = s.camera.value_or(viewer::Camera{});
    c.eye = {v[0], v[1], v[2]};
    c.target = {v[3], v[4], v[5]};
    c.up = {v[6], v[7], v[8]};
    s.camera = c;
  }
  if (a.fov != 0) {
    if (!(a.fov > 1 && a.fov < 179)) throw UsageError("--fov: from 1 to 179 degrees");
    s.fovDegrees = a.fov;
  }
  if (!a.up.empty()) s.up = parseUp(a.up);
  if (!a.lights.empty()) {
    if (a.lights.size() > gpu::kMaxLights)
      throw UsageError(fmt::format("at most {} --light options", gpu::kMaxLights));
    s.lights.clear();
    for (const std::string& l : a.lights) s.lights.push_back(viewer::parseLight(l));
  }
  if (!a.color.empty()) {
    const auto c = viewer::parseVec3(a.color);
    s.material.color = {float(c[0]), float(c[1]), float(c[2])};
  }
  if (!a.ambient.empty()) {
    const auto c = viewer::parseVec3(a.ambient);
    if (!(c[0] >= 0.0 && c[1] >= 0.0 && c[2] >= 0.0))
      throw UsageError("--ambient must not be negative");
    s.ambient = {float(c[0]), float(c[1]), float(c[2])};
  }
  if (a.reflectivity) s.material.reflectivity = *a.reflectivity;
  if (a.transparency) s.material.transparency = *a.transparency;
  if (!a.ior.empty()) {
    const std::vector<double> iors = parseIors(a);
    s.material.ior = float(iors[0]);
  }
  if (a.shininess) s.material.shininess = *a.shininess;
  if (s.material.reflectivity + s.material.transparency > 1.0f)
    throw UsageError("--reflectivity + --transparency must be at most 1");
  if (!a.environment.empty()) s.environment = a.environment;
  if (a.environmentIntensity) s.environmentIntensity = *a.environmentIntensity;
  if (a.lodPixels) s.lodPixels = *a.lodPixels;
  if (a.bounces) s.bounces = *a.bounces;
  if (a.samples) s.samples = *a.samples;
  if (a.noShadows) s.shadows = false;
  if (a.noReflections) s.reflections = false;
  if (a.noRefractions) s.refractions = false;
  if (!a.backFaces.empty()) s.backFaces = viewer::parseBackFaces(a.backFaces);
  if (!a.lighting.empty())
    s.lighting = *valueNamed(viewer::kLightingNames, a.lighting);  // checked by the option
  if (a.points) s.draw = viewer::Draw::Points;
  if (a.ground) s.groundAuto = true;
  if (a.groundHeight) s.groundHeight = *a.groundHeight;
  if (a.caustics) s.caustics = *a.caustics;
  if (!a.draw.empty()) s.draw = *valueNamed(viewer::kDrawNames, a.draw);
  if (a.layers) s.image.layers = *a.layers;
  if (a.layerGap) s.image.layerGap = *a.layerGap;
  if (a.shadowSamples) s.image.shadowSamples = *a.shadowSamples;
  if (a.eyeDome) s.image.eyeDome = true;
  if (!a.opacity.empty()) {
    s.image.opacity.clear();
    std::stringstream in(a.opacity);
    for (std::string item; std::getline(in, item, ',');) {
      const double v = viewer::parseNumbers(item, 1, "--opacity (one a file, or one for all)")[0];
      if (!(v > 0.0 && v <= 1.0)) throw UsageError("--opacity: each in (0, 1]");
      s.image.opacity.push_back(float(v));
    }
  }
}

// The pictures to write (--out, --screenshot), checked before the file is opened: in a directory
// that takes them, not the input, of a kind this build writes; they replace what is there.
void checkPictures(const ViewArgs& a) {
  const std::pair<std::filesystem::path, const char*> pictures[] = {
      {a.view.out, "--out"}, {a.view.screenshot, "--screenshot"}};
  for (const auto& [path, option] : pictures) {
    if (path.empty()) continue;
    checkOutputPath(path, option, true);
    for (const std::string& file : a.files) refuseOutputOverInput(path, file, option);
    checkImageWritable(path, option);
    setInterruptMessage("iso view: interrupted; nothing was written");
  }
}

}  // namespace

void addViewCommand(CLI::App& app, int& exitCode) {
  auto a = std::make_shared<ViewArgs>();
  CLI::App* c = app.add_subcommand(
      "view",
      "Look at an .iso file: a window (default), a picture (--headless --out F.png, or --cpu), "
      "or a benchmark (--bench); chunks stream to the GPU under --vram");
  c->add_option("file", a->files,
                ".iso file, or point files (raw scans: every format iso convert reads), drawn "
                "as image-space points")
      ->required()
      ->check(CLI::ExistingFile);
  c->add_flag("--headless", a->headless, "Render a picture to --out without a window (GPU)");
  c->add_flag("--cpu", a->cpu, "Render the picture with the CPU reference tracer instead");
  c->add_flag("--bench", a->bench,
              "Render a camera path (an orbit) with frames in flight and print ms/frame, GPU "
              "time, rays/s by kind, the first view on the CPU reference tracer, GPU memory, "
              "chunks resident and bytes streamed");
  c->add_option("--out,-o", a->view.out,
                "Picture to write (.png, .jpg, .exr, ...; .png or .ppm in builds without "
                "OpenImageIO)");
  c->add_option("--width", a->view.width, "Picture width in pixels")
      ->capture_default_str()
      ->check(CLI::Range(8, 16384));
  c->add_option("--height", a->view.height, "Picture height in pixels")
      ->capture_default_str()
      ->check(CLI::Range(8, 16384));
  c->add_option("--camera", a->camera,
                "eye,target,up in world units (9 numbers; default: the side showing the most of "
                "the surface, filling 80 % of the picture)");
  c->add_option("--fov", a->fov, "Vertical field of view in degrees (default 40)");
  c->add_option("--up", a->up,
                "The scene's up: x, y, z, -x, -y, -z or X,Y,Z (default: z for "
                "LAS inputs, else y)");
  c->add_option("--vram", a->vram,
                "GPU memory the viewer may allocate, all buffers included (e.g. 64M, 2G)")
      ->capture_default_str();
  c->add_option("--upload-per-frame", a->upload, "Chunk bytes uploaded per frame at most")
      ->capture_default_str();
  c->add_option("--scene", a->view.sceneFile,
                "JSON scene file: camera, lights, material, environment (specs/viewer.md); the "
                "window reloads it when it changes")
      ->check(CLI::ExistingFile);
  c->add_option("--light", a->lights,
                "A light (repeatable, up to 4): point:X,Y,Z[:R,G,B[:I]] or "
                "area:X,Y,Z:UX,UY,UZ:VX,VY,VZ[:SAMPLES[:R,G,B[:I]]]");
  c->add_option("--color", a->color, "Material color R,G,B (linear) where the file has none");
  c->add_option("--ambient", a->ambient,
                "Ambient light R,G,B (linear; default 0.12,0.12,0.13), darkened by the file's "
                "baked ambient occlusion when it has some");
  c->add_option("--reflectivity", a->reflectivity, "Mirror reflection, 0 to 1")
      ->check(CLI::Range(0.0, 1.0));
  c->add_option("--transparency", a->transparency, "Refraction, 0 to 1")
      ->check(CLI::Range(0.0, 1.0));
  c->add_option("--ior", a->ior,
                "Index of refraction, 1 to 4; --draw pss: also R,G,B (each channel refracted "
                "with its own: dispersion)");
  c->add_option("--shininess", a->shininess, "Phong exponent")->check(CLI::Range(1.0, 10000.0));
  c->add_option("--env", a->environment,
                "Environment map: an equirectangular image OpenImageIO reads (PNG or PPM in builds "
                "without it)")
      ->check(CLI::ExistingFile);
  c->add_option("--env-intensity", a->environmentIntensity, "Environment map scale")
      ->check(CLI::Range(0.0, 1000.0));
  c->add_option("--bounces", a->bounces, "Reflection and refraction bounces at most")
      ->check(CLI::Range(0, 8));
  c->add_option("--spp", a->samples, "Samples per pixel (supersampling)")
      ->check(CLI::Range(1, 256));
  c->add_option("--lod-pixels", a->lodPixels,
                "Screen-space error in pixels below which a coarser level is drawn")
      ->check(CLI::Range(0.0, 1000.0));
  c->add_option("--backfaces", a->backFaces,
                "Back faces (the inside of the surface, e.g. an open scan seen from behind): "
                "show (shaded, the default), tint, or hide (see through them)")
      ->check(CLI::IsMember(namesList(viewer::kBackFaceNames)));
  c->add_option("--lighting", a->lighting,
                "A file with baked lighting (iso bake): baked (its irradiance, no shadow rays; "
                "the default), live (the lights, as any file), or both; key L in the window "
                "steps through them")
      ->check(CLI::IsMember(namesList(viewer::kLightingNames)));
  auto* points = c->add_flag("--points", a->points,
                             "Draw the kept points (iso convert --keep-points) as splats instead "
                             "of the surface (--draw points); key K in the window cycles");
  auto drawNames = namesList(viewer::kDrawNames);
  drawNames.push_back("image");
  drawNames.push_back("pss");
  c->add_option("--draw", a->draw,
                "What rays meet: surface (the default), points (the kept points as splats), or "
                "both (the nearer); or image: point files drawn as image-space points (the "
                "default for raw scans); or pss: the points (an .iso file's kept points, or point "
                "files) as a point set surface (a window, --headless, --cpu or --bench)")
      ->check(CLI::IsMember(drawNames))
      ->excludes(points);
  c->add_option("--pss", a->pss,
                "--draw pss: fast (the nearest stored polynomial, the default) or exact (hits "
                "projected onto the moving-least-squares surface)")
      ->check(CLI::IsMember({"fast", "exact"}));
  c->add_option("--volume-points", a->volumePoints,
                "--draw pss: a point file of scattered values (a PLY vertex property, or LAS "
                "intensity) drawn as a volume inside the surface (the scene file's \"volume\": "
                "transfer function, smoothing, step)");
  c->add_option("--with-pss", a->withPss,
                "Also a point set surface of these points (a point file, or an .iso file's kept "
                "points) in the .iso file's scene, traced with its surface and splats (shadows, "
                "reflections, refractions; --pss exact|fast; --volume-points or --volume: a "
                "volume inside it)")
      ->check(CLI::ExistingFile);
  c->add_option("--volume", a->volume,
                "--draw pss: the scalar of --volume-points to draw (default: its only one); "
                "without --volume-points, the volume points an .iso input keeps with values of "
                "this name (iso convert --volume-points FILE --keep-scalar NAME)");
  c->add_option("--layers", a->layers,
                "--draw image: surface layers peeled and blended front to back (transparency; "
                "default 1)")
      ->check(CLI::Range(1, viewer::kMaxImageLayers));
  c->add_option("--layer-gap", a->layerGap,
                "--draw image: the least distance between two surface layers (world units; "
                "default 3 point spacings)")
      ->check(CLI::PositiveNumber);
  c->add_option("--opacity", a->opacity,
                "--draw image: the inputs' opacity, A (all) or A,B,... (one a file), each in "
                "(0, 1]");
  c->add_option("--shadow-samples", a->shadowSamples,
                "--draw image: samples of each light for soft shadows (a point light becomes a "
                "small square light)")
      ->check(CLI::Range(1, viewer::kMaxImageShadowSamples));
  c->add_option("--shadow-resolution", a->image.settings.shadowResolution,
                "--draw image: the lights' images, pixels across (default: pixels about as wide "
                "as the points' spacing)")
      ->check(CLI::Range(64, 8192));
  c->add_option("--antialias", a->antialias,
                "--draw image: anti-aliasing at silhouettes, at every layer edge, or off")
      ->capture_default_str()
      ->check(CLI::IsMember({"silhouettes", "edges", "off"}));
  c->add_flag("--no-smooth", a->noSmooth, "--draw image: no smoothing filter");
  c->add_option("--fill-rounds", a->image.fillRoundsPerSubmit,
                "--draw image, GPU: filling rounds submitted before the host looks whether one "
                "changed nothing (default 2); for measurements")
      ->check(CLI::Range(1, 64));
  c->add_flag("--eye-dome", a->eyeDome,
              "--draw image: normal-free shading from the depth alone (eye-dome style)");
  c->add_flag("--ground", a->ground,
             "A diffuse ground plane under the surface, across the up axis (the scene file's "
             "\"ground\": true)");
  c->add_option("--ground-height", a->groundHeight,
                "The ground plane at this height along the up axis (world units)");
  c->add_option("--caustics", a->caustics,
                "Trace this many photons from each light through the transparent and mirror "
                "material onto the ground, and draw the caustics they make there (e.g. 1000000; "
                "a ground is put under the surface when none is given)")
      ->check(CLI::Range(uint32_t(0), viewer::kMaxCausticPhotons));
  c->add_flag("--no-shadows", a->noShadows, "No shadow rays");
  c->add_flag("--no-reflections", a->noReflections, "No reflection rays");
  c->add_flag("--no-refractions", a->noRefractions, "No refraction rays");
  c->add_option("--frames", a->view.frames,
                "Window: quit after this many frames (--draw image: frames of all the points, "
                "once read)");
  c->add_option("--screenshot", a->view.screenshot, "Window: save the last frame here on quitting");
  c->add_option("--max-frames", a->view.maxFrames,
                "Headless: frames at most for streaming to bring in what the view needs")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  c->add_option("--bench-frames", a->view.benchFrames, "Frames of the --bench camera path")
      ->capture_default_str()
      ->check(CLI::Range(2, 100000));
  c->add_option("--traversal", a->traversal,
                "The tracer's loop shape: nested (a loop of cells, each descending the tree) or "
                "flat (one loop whose turns descend a level or visit a cell); for measurements")
      ->capture_default_str()
      ->check(CLI::IsMember({"nested", "flat"}));
  c->add_option("--workgroup", a->view.workgroupSize,
                "Invocations per GPU workgroup (a tile of pixels): 8 to 1024, a power of two; for "
                "measurements")
      ->capture_default_str()
      ->check(CLI::IsMember({8u, 16u, 32u, 64u, 128u, 256u, 512u, 1024u}));
  auto* oneKernel = c->add_flag(
      "--one-kernel", a->view.oneKernel,
      "Draw every frame with one kernel (the default on a GPU; on a CPU device such as lavapipe "
      "frames of one sample a pixel without refraction rays run as a wavefront by default); for "
      "measurements");
  c->add_flag("--wavefront", a->view.wavefront,
              "Draw frames of one sample a pixel without refraction rays as a wavefront: the "
              "camera rays, then the hits' shading and shadow rays side by side, then bounce "
              "after bounce the mirror rays and their hits' shading (the default on a CPU device "
              "such as lavapipe); for measurements")
      ->excludes(oneKernel);
  c->add_flag("!--no-tile-cones", a->view.tileCones,
              "Start every camera ray at the eye (by default the rays of a tile of pixels start "
              "where a cone around them first meets the octree, traced once a tile; the "
              "pictures are the same); for measurements");
  c->add_flag("!--no-cpu-compare", a->view.cpuCompare,
              "--bench: skip tracing the first view on the CPU reference tracer (it decodes the "
              "whole file into memory)");
  c->add_flag("--json", a->view.benchJson, "--bench: print the numbers as one JSON object");
  c->add_option("--frames-in-flight", a->view.framesInFlight,
                "Frames the window and --bench keep in flight on the GPU (--headless renders "
                "one at a time)")
      ->capture_default_str()
      ->check(CLI::Range(1u, viewer::kMaxFramesInFlight));
  c->add_flag("--validation", a->view.validation,
              "Enable the Vulkan validation layer (errors make the command fail)");
  c->add_option("--device", a->view.device, "Use the Vulkan device whose name contains this");
  c->callback([a, &exitCode] {
    exitCode = runGuarded("view", [&]() -> int {
      const int modes = int(a->headless) + int(a->cpu) + int(a->bench);
      if (modes > 1) {
        fmt::print(stderr, "iso view: choose one of --headless, --cpu and --bench\n");
        return kExitUsage;
      }
      if (a->view.benchJson && !a->bench) {
        fmt::print(stderr, "iso view: --json goes with --bench\n");
        return kExitUsage;
      }
      if ((a->headless || a->cpu) && a->view.out.empty()) {
        fmt::print(stderr, "iso view: --headless and --cpu need --out FILE\n");
        return kExitUsage;
      }
      a->view.file = a->files.front();
      // A file named .iso is one (its reader says what is wrong with it); others by content.
      const bool image = a->draw == "image" || (a->view.file.extension() != ".iso" &&
                                                !isIsoFile(a->view.file));
      if (!image && a->files.size() > 1) {
        fmt::print(stderr, "iso view: one .iso file at a time (several files: point files)\n");
        return kExitUsage;
      }
      a->view.vram = parseSize(a->vram, "--vram");
      a->view.flatTraversal = a->traversal == "flat";
      a->view.uploadBytes = parseSize(a->upload, "--upload-per-frame");
      checkPictures(*a);
      if ((!a->volumePoints.empty() || !a->volume.empty()) && a->draw != "pss" &&
          a->withPss.empty()) {
        fmt::print(stderr,
                   "iso view: --volume-points and --volume go with --draw pss or --with-pss\n");
        return kExitUsage;
      }
      if (!a->withPss.empty() && (a->draw == "pss" || image)) {
        fmt::print(stderr, "iso view: --with-pss puts a point set surface into an .iso file's "
                           "scene: give one .iso file, without --draw pss or image\n");
        return kExitUsage;
      }
      if (a->draw == "pss") {
        a->drawPss = true;
        a->draw.clear();
        buildScene(*a);
        return viewPss(*a);
      }
      if (image) {
        a->draw.clear();
        buildScene(*a);
        return viewImage(*a);
      }
      buildScene(*a);
      if (!a->withPss.empty()) withPss(*a);
      if (a->cpu) return viewer::viewCpu(a->view);
      if (a->headless) return viewer::viewHeadless(a->view);
      if (a->bench) return viewer::viewBench(a->view);
      return viewer::viewWindow(a->view, windowImageMode(*a));
    });
  });
}

}  // namespace iso::cli
