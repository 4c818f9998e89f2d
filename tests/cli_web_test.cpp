// The 3D Tiles export in a real browser: `iso export --tiles`, drawn by three.js and
// 3d-tiles-renderer in Debian's headless Chromium (tools/web/screenshot-tiles.mjs), against the
// viewer's own picture (the CPU reference tracer) from the same camera: the two silhouettes
// agree (intersection over union).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "iso/reader.h"
#include "base/raster.h"
#include "tests/cli_support.h"

namespace iso {
namespace {

using test::quoted;
using test::runIso;

// Pixels that are not the black background.
std::vector<bool> silhouette(const std::filesystem::path& png, uint32_t width, uint32_t height) {
  const std::vector<std::byte> bytes = test::readFile(png);
  const Raster r = decodePng(bytes, png.string());
  EXPECT_EQ(r.width, width);
  EXPECT_EQ(r.height, height);
  std::vector<bool> mask(size_t(r.width) * r.height);
  for (size_t i = 0; i < mask.size(); ++i)
    for (uint32_t c = 0; c < 3; ++c) mask[i] = mask[i] || r.samples[i * r.channels + c] > 2;
  return mask;
}

double intersectionOverUnion(const std::vector<bool>& a, const std::vector<bool>& b) {
  size_t both = 0, either = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
    both += a[i] && b[i];
    either += a[i] || b[i];
  }
  return either > 0 ? double(both) / double(either) : 0.0;
}

std::string triple(const glm::dvec3& v) {
  std::ostringstream out;
  out.precision(17);
  out << v.x << ',' << v.y << ',' << v.z;
  return out.str();
}

// Convert `scan` (in chunks of `chunkNodes` nodes), export its tiles, and compare the browser's
// picture of them with the viewer's from a camera looking at the frame's centre. Returns the IoU.
double browserAgainstViewer(const std::filesystem::path& scan, const test::TempDir& dir,
                            int chunkNodes) {
  const std::string iso = quoted(dir / "scan.iso");
  auto run = runIso("convert -q --chunk-nodes " + std::to_string(chunkNodes) + " " + quoted(scan) +
                    " -o " + iso);
  EXPECT_EQ(run.exitCode, 0) << run.err;
  run = runIso("export -f " + iso + " --tiles " + quoted(dir / "tiles"));
  EXPECT_EQ(run.exitCode, 0) << run.err;
  const Frame frame = Reader::open(dir / "scan.iso").header().frame;
  const glm::dvec3 centre =
      glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]) + 0.5 * frame.size;
  const glm::dvec3 eye = centre + 1.3 * frame.size * glm::normalize(glm::dvec3(0.8, 0.45, 0.55));
  const glm::dvec3 up(0.0, 0.0, 1.0);
  constexpr uint32_t kWidth = 256, kHeight = 192;
  // The viewer: black sky, no lights, white ambient light: every surface pixel lit.
  {
    std::ofstream scene(dir / "silhouette.json");
    scene << R"({"sky_top": [0, 0, 0], "sky_bottom": [0, 0, 0], "ambient": [1, 1, 1],)"
          << R"( "lights": [], "material": {"color": [1, 1, 1]}})";
  }
  run = runIso("view " + iso + " --cpu --width " + std::to_string(kWidth) + " --height " +
               std::to_string(kHeight) + " --fov 40 --camera=" + triple(eye) + "," +
               triple(centre) + "," + triple(up) + " --scene " + quoted(dir / "silhouette.json") +
               " --out " + quoted(dir / "viewer.png"));
  EXPECT_EQ(run.exitCode, 0) << run.err;
  const std::filesystem::path web = ISO_WEB_TOOLS_DIR;
  EXPECT_TRUE(std::filesystem::exists(web / "node_modules" / "3d-tiles-renderer"))
      << "run tools/run setup (it installs " << web.string() << "'s npm packages)";
  run = test::runCommand("node " + quoted(web / "screenshot-tiles.mjs") + " " +
                         quoted(dir / "tiles") + " " + quoted(dir / "browser.png") + " " +
                         triple(eye) + " " + triple(centre) + " " + triple(up) + " 40 " +
                         std::to_string(kWidth) + " " + std::to_string(kHeight));
  EXPECT_EQ(run.exitCode, 0) << run.out << run.err;
  if (run.exitCode != 0) return 0.0;
  const std::vector<bool> viewer = silhouette(dir / "viewer.png", kWidth, kHeight);
  const std::vector<bool> browser = silhouette(dir / "browser.png", kWidth, kHeight);
  size_t covered = 0;
  for (bool b : viewer) covered += b;
  EXPECT_GT(covered, kWidth * kHeight / 10) << "the camera sees the surface";
  const double iou = intersectionOverUnion(viewer, browser);
  std::string drawn = run.out;
  while (!drawn.empty() && drawn.back() == '\n') drawn.pop_back();
  std::printf("%s: %s; silhouette IoU %.4f\n", scan.filename().c_str(), drawn.c_str(), iou);
  return iou;
}

// A baked scan's tiles carry its lit colors (COLOR_0, unlit material): drawn in Chromium they
// look as `iso view --lighting baked` draws the scan without ambient and specular light.
TEST(CliWeb, aBakedKittensTilesInChromiumShowTheViewersBakedLight) {
  test::TempDir dir;
  const std::string iso = quoted(dir / "kitten.iso"), lit = quoted(dir / "lit.iso");
  auto run = runIso("convert -q --chunk-nodes 2000 " +
                    quoted(std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz") +
                    " -o " + iso);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const Frame frame = Reader::open(dir / "kitten.iso").header().frame;
  const glm::dvec3 centre =
      glm::dvec3(frame.origin[0], frame.origin[1], frame.origin[2]) + 0.5 * frame.size;
  const glm::dvec3 eye = centre + 1.3 * frame.size * glm::normalize(glm::dvec3(0.8, 0.45, 0.55));
  const glm::dvec3 light = centre + 2.0 * frame.size * glm::normalize(glm::dvec3(0.3, 0.9, 0.6));
  {
    std::ofstream scene(dir / "scene.json");
    scene << R"({"sky_top": [0, 0, 0], "sky_bottom": [0, 0, 0], "ambient": [0, 0, 0],)"
          << R"( "lights": [{"type": "point", "position": [)" << triple(light) << "]}],"
          << R"( "material": {"color": [0.8, 0.7, 0.6], "specular": 0}})";
  }
  run = runIso("bake " + iso + " -o " + lit + " --scene " + quoted(dir / "scene.json") +
               " --bounces 1 --bake-rays 16");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  run = runIso("export -f " + lit + " --tiles " + quoted(dir / "tiles"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  constexpr uint32_t kWidth = 256, kHeight = 192;
  run = runIso("view " + lit + " --cpu --width " + std::to_string(kWidth) + " --height " +
               std::to_string(kHeight) + " --fov 40 --camera=" + triple(eye) + "," +
               triple(centre) + ",0,0,1 --scene " + quoted(dir / "scene.json") +
               " --lighting baked --out " + quoted(dir / "viewer.png"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const std::filesystem::path web = ISO_WEB_TOOLS_DIR;
  run = test::runCommand("node " + quoted(web / "screenshot-tiles.mjs") + " " +
                         quoted(dir / "tiles") + " " + quoted(dir / "browser.png") + " " +
                         triple(eye) + " " + triple(centre) + " 0,0,1 40 " +
                         std::to_string(kWidth) + " " + std::to_string(kHeight) + " own");
  ASSERT_EQ(run.exitCode, 0) << run.out << run.err;
  const Raster viewer = decodePng(test::readFile(dir / "viewer.png"), "viewer.png");
  const Raster browser = decodePng(test::readFile(dir / "browser.png"), "browser.png");
  // Where both draw the scan: the mean difference of the channels, and the share of pixels whose
  // green differs by more than 24/255 (the tiles' vertices interpolate the light linearly across
  // triangles that the simplification made larger than the leaves).
  size_t both = 0, far = 0;
  double sum = 0.0, brightness = 0.0;
  const auto at = [](const Raster& r, size_t i, uint32_t c) {
    return int(r.samples[i * r.channels + c]);
  };
  for (size_t i = 0; i < size_t(kWidth) * kHeight; ++i) {
    const bool a = at(viewer, i, 0) + at(viewer, i, 1) + at(viewer, i, 2) > 6;
    const bool b = at(browser, i, 0) + at(browser, i, 1) + at(browser, i, 2) > 6;
    if (!a || !b) continue;
    ++both;
    for (uint32_t c = 0; c < 3; ++c) sum += std::abs(at(viewer, i, c) - at(browser, i, c));
    brightness += at(viewer, i, 1);
    far += std::abs(at(viewer, i, 1) - at(browser, i, 1)) > 24;
  }
  ASSERT_GT(both, size_t(kWidth) * kHeight / 10);
  const double mean = sum / (3.0 * double(both));
  std::printf("baked kitten in Chromium against iso view: %zu pixels both draw, mean green %.1f, "
              "mean difference %.2f/255, %.2f %% differ by more than 24/255\n",
              both, brightness / double(both), mean, 100.0 * double(far) / double(both));
  EXPECT_GT(brightness / double(both), 40.0);  // lit, not black
  EXPECT_LT(mean, 8.0);
  EXPECT_LT(double(far) / double(both), 0.05);
}

TEST(CliWeb, theKittensTilesInChromiumHaveTheViewersSilhouette) {
  test::TempDir dir;
  EXPECT_GE(browserAgainstViewer(std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz",
                                 dir, 2000),
            0.95);
}

// A tileset's tree as a client sees it: each tile's box (world units), error and the triangles
// of its content (surface and skirts, as a renderer counts them).
struct TileNode {
  glm::dvec3 centre{0.0};
  double half = 0.0, error = 0.0;
  uint64_t triangles = 0;
  std::vector<TileNode> children;
};

uint64_t glbTriangles(const std::filesystem::path& path) {
  const std::vector<std::byte> raw = test::readFile(path);
  uint32_t length = 0;
  std::memcpy(&length, raw.data() + 12, 4);
  const nlohmann::json json =
      nlohmann::json::parse(reinterpret_cast<const char*>(raw.data()) + 20,
                            reinterpret_cast<const char*>(raw.data()) + 20 + length);
  uint64_t indices = 0;
  for (const auto& primitive : json["meshes"][0]["primitives"])
    indices += json["accessors"][primitive["indices"].get<size_t>()]["count"].get<uint64_t>();
  return indices / 3;
}

TileNode readTileNode(const std::filesystem::path& directory, const nlohmann::json& tile,
                      const glm::dvec3& offset) {
  TileNode node;
  const nlohmann::json& box = tile["boundingVolume"]["box"];
  node.centre = glm::dvec3(box[0], box[1], box[2]) + offset;
  node.half = box[3].get<double>();
  node.error = tile["geometricError"].get<double>();
  if (tile.contains("content"))
    node.triangles = glbTriangles(directory / tile["content"]["uri"].get<std::string>());
  if (tile.contains("children"))
    for (const auto& child : tile["children"])
      node.children.push_back(readTileNode(directory, child, offset));
  return node;
}

// The fewest triangles that meet a screen-space error of 1 pixel from `eye` (3d-tiles-renderer's
// rule: a tile is replaced by its children where its error over its box's distance, in pixels of
// the view's height, exceeds the target), of the tiles in the view's frustum.
uint64_t fewestTriangles(const TileNode& tile, const glm::dvec3& eye, const glm::dvec3& forward,
                         const glm::dvec3& right, const glm::dvec3& up, double fov, double aspect,
                         double height) {
  // Outside the frustum: every corner beyond one of its four side planes.
  const double ty = std::tan(0.5 * fov), tx = ty * aspect;
  const std::array<glm::dvec3, 4> planes = {
      // inward normals through the eye
      glm::normalize(forward * tx + right), glm::normalize(forward * tx - right),
      glm::normalize(forward * ty + up), glm::normalize(forward * ty - up)};
  for (const glm::dvec3& n : planes) {
    bool outside = true;
    for (int c = 0; c < 8 && outside; ++c) {
      const glm::dvec3 corner =
          tile.centre + tile.half * glm::dvec3(c & 1 ? 1 : -1, c & 2 ? 1 : -1, c & 4 ? 1 : -1);
      outside = glm::dot(corner - eye, n) < 0.0;
    }
    if (outside) return 0;
  }
  const glm::dvec3 gap =
      glm::max(glm::abs(eye - tile.centre) - glm::dvec3(tile.half), glm::dvec3(0.0));
  const double distance = glm::length(gap);
  const bool refine = !tile.children.empty() &&
                      (distance <= 0.0 || tile.error / (distance * 2.0 * ty / height) > 1.0);
  if (!refine) return tile.triangles;
  uint64_t sum = 0;
  for (const TileNode& child : tile.children)
    sum += fewestTriangles(child, eye, forward, right, up, fov, aspect, height);
  return sum;
}

// Convert `scan`, export its tiles, and fly a camera from far to near towards the frame's centre:
// at each distance, what 3d-tiles-renderer in Chromium loads and draws, against the fewest
// triangles that meet its screen-space error and against the viewer's silhouette.
void flyThrough(const std::filesystem::path& scan, const test::TempDir& dir) {
  const std::string iso = quoted(dir / "scan.iso");
  auto run = runIso("convert -q " + quoted(scan) + " -o " + iso);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  run = runIso("export -f " + iso + " --tiles " + quoted(dir / "tiles"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const Frame frame = Reader::open(dir / "scan.iso").header().frame;
  const glm::dvec3 origin(frame.origin[0], frame.origin[1], frame.origin[2]);
  const glm::dvec3 centre = origin + 0.5 * frame.size;
  const glm::dvec3 direction = glm::normalize(glm::dvec3(0.8, 0.45, 0.55)), up(0.0, 0.0, 1.0);
  constexpr uint32_t kWidth = 256, kHeight = 192;
  constexpr double kFov = 40.0 * M_PI / 180.0;
  const std::vector<double> distances = {3.0, 2.0, 1.3, 0.9, 0.65};  // frame sizes
  std::string eyes;
  for (double d : distances)
    eyes += (eyes.empty() ? "" : ";") + triple(centre + d * frame.size * direction);
  const std::filesystem::path web = ISO_WEB_TOOLS_DIR;
  run = test::runCommand("node " + quoted(web / "screenshot-tiles.mjs") + " " +
                         quoted(dir / "tiles") + " " + quoted(dir / "browser-%d.png") + " '" +
                         eyes + "' " + triple(centre) + " " + triple(up) + " 40 " +
                         std::to_string(kWidth) + " " + std::to_string(kHeight));
  ASSERT_EQ(run.exitCode, 0) << run.out << run.err;
  std::vector<nlohmann::json> views;
  std::istringstream lines(run.out);
  for (std::string line; std::getline(lines, line);)
    if (!line.empty()) views.push_back(nlohmann::json::parse(line));
  ASSERT_EQ(views.size(), distances.size());
  const nlohmann::json tileset =
      nlohmann::json::parse(std::ifstream(dir / "tiles" / "tileset.json"));
  const TileNode root = readTileNode(dir / "tiles", tileset["root"], origin);
  {
    std::ofstream scene(dir / "silhouette.json");
    scene << R"({"sky_top": [0, 0, 0], "sky_bottom": [0, 0, 0], "ambient": [1, 1, 1],)"
          << R"( "lights": [], "material": {"color": [1, 1, 1]}})";
  }
  for (size_t i = 0; i < distances.size(); ++i) {
    const glm::dvec3 eye = centre + distances[i] * frame.size * direction;
    const glm::dvec3 forward = glm::normalize(centre - eye);
    const glm::dvec3 right = glm::normalize(glm::cross(forward, up));
    const uint64_t fewest = fewestTriangles(root, eye, forward, right, glm::cross(right, forward),
                                            kFov, double(kWidth) / kHeight, kHeight);
    const std::filesystem::path viewer = dir / ("viewer-" + std::to_string(i) + ".png");
    run = runIso("view " + iso + " --cpu --width " + std::to_string(kWidth) + " --height " +
                 std::to_string(kHeight) + " --fov 40 --camera=" + triple(eye) + "," +
                 triple(centre) + "," + triple(up) + " --scene " + quoted(dir / "silhouette.json") +
                 " --out " + quoted(viewer));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    const double iou = intersectionOverUnion(
        silhouette(viewer, kWidth, kHeight),
        silhouette(dir / ("browser-" + std::to_string(i) + ".png"), kWidth, kHeight));
    const uint64_t drawn = views[i]["triangles"].get<uint64_t>();
    std::printf(
        "%s at %.2f frame sizes: %d tiles loaded so far, %d drawn, %llu triangles (the "
        "fewest at 1 pixel: %llu, %.2fx); silhouette IoU %.4f\n",
        scan.filename().c_str(), distances[i], views[i]["models"].get<int>(),
        views[i]["tiles"].get<int>(), static_cast<unsigned long long>(drawn),
        static_cast<unsigned long long>(fewest), double(drawn) / double(fewest), iou);
    EXPECT_GE(iou, 0.95) << distances[i];
    EXPECT_LE(double(drawn), 2.0 * double(fewest)) << distances[i];
    EXPECT_GE(double(drawn), 0.5 * double(fewest)) << distances[i];
  }
}

TEST(CliWeb,
     aFlightOverTheLionAndTheDragonDrawsWhatTheScreenSpaceErrorNeedsWithTheViewersSilhouette) {
  const std::filesystem::path data = ISO_SHARED_DATA_DIR;
  if (!std::filesystem::exists(data / "lion_rgb.las"))
    GTEST_SKIP() << "needs " << data.string() << " (the shared scans)";
  for (const char* scan : {"lion_rgb.las", "dragon_vrip.ply.gz"}) {
    test::TempDir dir;
    flyThrough(data / scan, dir);
  }
}

TEST(CliWeb, theBunnysTilesInChromiumHaveTheViewersSilhouette) {
  const std::filesystem::path data = ISO_SHARED_DATA_DIR;
  if (!std::filesystem::exists(data / "bunny_zipper.ply"))
    GTEST_SKIP() << "needs " << data.string() << " (the shared scans)";
  test::TempDir dir;
  EXPECT_GE(browserAgainstViewer(data / "bunny_zipper.ply", dir, 8000), 0.95);
}

}  // namespace
}  // namespace iso
