// The 3D Tiles export in a real browser: `iso export --tiles`, drawn by three.js and
// 3d-tiles-renderer in Debian's headless Chromium (tools/web/screenshot-tiles.mjs), against the
// viewer's own picture (the CPU reference tracer) from the same camera: the two silhouettes
// agree (intersection over union).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <sstream>
#include <string>

#include "iso/reader.h"
#include "pipeline/io/raster.h"
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

TEST(CliWeb, theKittensTilesInChromiumHaveTheViewersSilhouette) {
  test::TempDir dir;
  EXPECT_GE(browserAgainstViewer(std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz",
                                 dir, 2000),
            0.95);
}

TEST(CliWeb, theBunnysAndTheLionsTilesInChromiumHaveTheViewersSilhouette) {
  const std::filesystem::path data = ISO_SHARED_DATA_DIR;
  if (!std::filesystem::exists(data / "lion_rgb.las"))
    GTEST_SKIP() << "needs " << data.string() << " (the shared scans)";
  for (const char* scan : {"bunny_zipper.ply", "lion_rgb.las"}) {
    test::TempDir dir;
    EXPECT_GE(browserAgainstViewer(data / scan, dir, 8000), 0.95) << scan;
  }
}

}  // namespace
}  // namespace iso
