// The default view (viewer/scene.h, defaultCamera): the direction that sees the most cells, framed
// to fill 80 % of the picture, against shapes whose answer is known; and the kitten of the demo,
// whose picture the surface fills to 70–90 % of its height.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "pipeline/io/readers.h"
#include "tests/pipeline/pipeline_support.h"
#include "tests/support/support.h"
#include "tracer/cpu_tracer.h"
#include "viewer/asset.h"
#include "viewer/scene.h"
#include "viewer/view.h"

namespace iso::test {
namespace {

using namespace iso::viewer;

// Cells of size `size` on the part of the unit sphere where keep(center) holds.
template <class Keep>
std::vector<SurfaceCell> sphereCells(double size, Keep keep) {
  std::vector<SurfaceCell> cells;
  const int n = int(std::ceil(2.0 / size));
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j)
      for (int k = 0; k <= n; ++k) {
        const Vec3d p(-1 + i * size, -1 + j * size, -1 + k * size);
        if (std::abs(glm::length(p) - 1.0) > size / 2) continue;
        const Vec3d onSphere = glm::normalize(p);
        if (keep(onSphere)) cells.push_back({onSphere, size});
      }
  return cells;
}

// The largest of |x| / (z tan · aspect) and |y| / (z tan) over the cells the camera sees in front:
// how far out of the picture's center the farthest reaches, 1 at its edge.
double reach(const Camera& c, const std::vector<SurfaceCell>& cells, double aspect) {
  const Vec3d forward = glm::normalize(c.target - c.eye);
  const Vec3d right = glm::normalize(glm::cross(forward, c.up)), top = glm::cross(right, forward);
  const double tanHalf = std::tan(c.fovDegrees * M_PI / 360.0);
  double most = 0;
  for (const SurfaceCell& cell : cells) {
    const Vec3d d = cell.center - c.eye;
    const double z = glm::dot(d, forward);
    EXPECT_GT(z, 0) << "a cell behind the eye";
    most = std::max({most, std::abs(glm::dot(d, right)) / (z * tanHalf * aspect),
                     std::abs(glm::dot(d, top)) / (z * tanHalf)});
  }
  return most;
}

Vec3d viewFrom(const Camera& c) { return glm::normalize(c.eye - c.target); }

TEST(DefaultView, aShellOpenOnOneSideIsSeenFromThatSideAndFramedToEightyPercent) {
  // The half of the sphere with x > 0: every cell is seen from +x, fewer from any slant.
  const auto cells = sphereCells(0.05, [](const Vec3d& p) { return p.x > 0; });
  ASSERT_GT(cells.size(), 1000u);
  for (const double aspect : {1.0, 2.0, 0.5}) {
    SCOPED_TRACE(aspect);
    const Camera c = defaultCamera(cells, {0, 1, 0}, 40.0, aspect);
    EXPECT_NEAR(glm::distance(viewFrom(c), Vec3d(1, 0, 0)), 0.0, 1e-9);
    EXPECT_EQ(c.up, Vec3d(0, 1, 0));
    // What is seen from +x is framed: the farthest cell seen at 80 % of the half-width or
    // half-height. The rim's cells, seen edge-on, may be hidden by their neighbours in the grid
    // and reach a cell's width (5 % of the radius) further; those facing the eye never do.
    const double all = reach(c, cells, aspect);
    EXPECT_GE(all, 0.8 - 1e-6);
    EXPECT_LE(all, 0.8 * 1.05);
    std::vector<SurfaceCell> facing;
    for (const SurfaceCell& cell : cells)
      if (cell.center.x > 0.3) facing.push_back(cell);
    EXPECT_LE(reach(c, facing, aspect), 0.8 + 1e-6);
    // Centered on the seen cells' box: y from -1 to 1, z from -1 to 1.
    EXPECT_NEAR(c.target.y, 0.0, 0.03);
    EXPECT_NEAR(c.target.z, 0.0, 0.03);
  }
}

TEST(DefaultView, noViewFromBelowTheHorizonAndAViewFromAboveLeansTowardsTheFront) {
  // A bowl (the sphere's lower half) is seen whole from straight above and straight below; from
  // above it is, leaning 20 degrees towards the front (+z for y up, -y for z up).
  for (const Vec3d& up : {Vec3d(0, 1, 0), Vec3d(0, 0, 1)}) {
    SCOPED_TRACE(up.z);
    const auto bowl = sphereCells(0.05, [&](const Vec3d& p) { return glm::dot(p, up) < 0; });
    const Camera c = defaultCamera(bowl, up, 40.0, 4.0 / 3.0);
    const Vec3d front = up.z == 1 ? Vec3d(0, -1, 0) : Vec3d(0, 0, 1);
    const double tilt = 20.0 * M_PI / 180.0;
    EXPECT_NEAR(glm::distance(viewFrom(c), up * std::cos(tilt) + front * std::sin(tilt)), 0.0,
                1e-9);
    EXPECT_EQ(c.up, up);
  }
  // A bowl under a lid that hides part of it from above is seen whole only from below: it is
  // seen from above all the same (the views from below would show the ground, the underside).
  auto lidded = sphereCells(0.05, [](const Vec3d& p) { return p.y < 0; });
  for (double x = -0.5; x <= 0.5; x += 0.05)
    for (double z = -0.5; z <= 0.5; z += 0.05) lidded.push_back({{x, 0.5, z}, 0.05});
  EXPECT_GT(viewFrom(defaultCamera(lidded, {0, 1, 0}, 40.0, 1.0)).y, 0.5);
  EXPECT_THROW(defaultCamera({}, {0, 1, 0}, 40.0, 1.0), UsageError);
}

// The rows of a picture where the surface is: pixels that differ from the sky at the row's left
// end (the sky changes only from row to row).
std::pair<uint32_t, uint32_t> surfaceRows(const std::vector<uint32_t>& rgba, uint32_t w,
                                          uint32_t h) {
  uint32_t first = h, last = 0;
  for (uint32_t y = 0; y < h; ++y) {
    const uint32_t sky = rgba[size_t(y) * w];
    for (uint32_t x = 1; x < w; ++x) {
      const uint32_t p = rgba[size_t(y) * w + x];
      int most = 0;
      for (int c = 0; c < 3; ++c)
        most = std::max(most, std::abs(int(p >> 8 * c & 0xFF) - int(sky >> 8 * c & 0xFF)));
      if (most > 8) {
        first = std::min(first, y);
        last = std::max(last, y);
        break;
      }
    }
  }
  return {first, last};
}

TEST(DefaultView, theDemoKittenFillsSeventyToNinetyPercentOfThePicturesHeight) {
  TempDir dir;
  const PointCloud kitten =
      readPointFile(builtPath("ISO_TEST_DATA_DIR", ISO_TEST_DATA_DIR) / "kitten_normals.xyz");
  convertToIso(kitten, dir / "kitten.iso", BuildOptions{});
  const auto asset = Asset::open(dir / "kitten.iso");
  ViewOptions options;
  options.width = 400;
  options.height = 300;
  const Scene scene = completeScene(options, *asset);
  // Seen from the front (+z, the face), at the horizon: the view that sees the most of it.
  EXPECT_NEAR(glm::distance(viewFrom(*scene.camera), Vec3d(0, 0, 1)), 0.0, 1e-9);
  const CpuPool pool = buildCpuPool(asset->reader);
  const auto header = asset->reader.header();
  const std::vector<uint32_t> pixels =
      renderCpu(pool,
                frameParams(scene, header.frame, header.maxLevel,
                            cpuFrameSetup(*asset, options.width, options.height, nullptr)),
                nullptr)
          .pixels;
  const auto [first, last] = surfaceRows(pixels, options.width, options.height);
  const double fill = double(last - first + 1) / options.height;
  EXPECT_GE(fill, 0.70);
  EXPECT_LE(fill, 0.90);
}

}  // namespace
}  // namespace iso::test
