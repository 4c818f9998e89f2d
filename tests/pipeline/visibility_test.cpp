// The visibility measure (pipeline/visibility.h): what the viewer's own tracer shows of a scan's
// points from far views, against shapes whose answer is known.
#include <gtest/gtest.h>

#include <algorithm>
#include <glm/geometric.hpp>

#include "pipeline/analysis/visibility.h"
#include "pipeline/base/options.h"
#include "tests/pipeline/pipeline_support.h"

namespace iso::test {
namespace {

struct Measured {
  Visibility visibility;
  double spacing = 0.0;
};

Measured measure(const std::filesystem::path& file, const PointCloud& points,
                 const VisibilityOptions& options = {}) {
  const Reader reader = Reader::open(file);
  const nlohmann::json metadata = nlohmann::json::parse(reader.metadata());
  const double spacing = metadata["report"]["spacing"].get<double>();
  return {measureVisibility(reader, points.positions, spacing, options), spacing};
}

TEST(Visibility, seesEveryPointOfAClosedSphereAndItsDepth) {
  TempDir dir;
  const PointCloud points = scanOf("sphere", 30000);
  convertToIso(points, dir / "sphere.iso", BuildOptions{});
  const Measured m = measure(dir / "sphere.iso", points);
  ASSERT_EQ(m.visibility.views.size(), 10u);
  for (const ViewVisibility& v : m.visibility.views) {
    EXPECT_EQ(v.points, points.size());
    EXPECT_EQ(v.seenThrough, 0u);
    // Along the view, the surface lies within 3 spacings of every point but those on the outline,
    // where the ray through a point a little outside the surface (by δ, about a tenth of a
    // spacing s) passes beside it: those within sqrt(2δ) of the outline (radius 1), a band of
    // about 6 % of the sphere's area, and of those about half lie outside.
    EXPECT_EQ(v.depthMeasured + v.depthMissed, points.size());
    EXPECT_LT(v.depthMissed, points.size() * 5 / 100);
  }
  // The surface lies within about a tenth of a spacing of the points (iso eval --shape: RMS 0.08).
  EXPECT_LT(m.visibility.depthMedian, 0.2);
  EXPECT_GT(m.visibility.depthMedian, 0.0);
  EXPECT_TRUE(m.visibility.seen.empty());
}

// A sphere scanned without its cap (z > 0.7) against all of its points: seen from the side, the
// cap's points above the surface's top show the sky; seen from above, the ray through the opening
// meets the inside of the sphere (a back face, which the viewer draws), so none do.
TEST(Visibility, findsThePointsWhereTheSurfaceIsMissing) {
  TempDir dir;
  const PointCloud all = scanOf("sphere", 40000);
  PointCloud capless;
  for (size_t i = 0; i < all.size(); ++i)
    if (all.positions[i].z <= 0.7) {
      capless.positions.push_back(all.positions[i]);
      capless.normals.push_back(all.normals[i]);
    }
  convertToIso(capless, dir / "capless.iso", BuildOptions{});
  const Measured m = measure(dir / "capless.iso", all);
  size_t above85 = 0, above70 = 0;
  for (const glm::dvec3& p : all.positions) {
    above85 += p.z > 0.85;
    above70 += p.z > 0.7;
  }
  for (size_t v = 0; v < 4; ++v) {  // ±x, ±y
    const ViewVisibility& side = m.visibility.views[v];
    EXPECT_GE(side.seenThrough, above85) << "view " << v;
    EXPECT_LE(side.seenThrough, above70) << "view " << v;
    // The cap's points cover their neighbourhood: a hole, not an outline.
    EXPECT_GT(side.seenThroughInside, side.seenThrough / 2) << "view " << v;
  }
  for (size_t v = 4; v < 6; ++v) EXPECT_EQ(m.visibility.views[v].seenThrough, 0u) << "view " << v;
  // Every point seen through is a point of the cap.
  for (const uint32_t i : m.visibility.seen) EXPECT_GT(all.positions[i].z, 0.7);
}

// An open sheet turned out of the axes (an axis-aligned one is a line from four of the views):
// the viewer shows both of its sides, so no point is seen through from any side.
TEST(Visibility, seesAnOpenSheetFromBothSides) {
  TempDir dir;
  const PointCloud points = scanOf(turnedShape("plane"), 30000);
  convertToIso(points, dir / "plane.iso", BuildOptions{});
  const Measured m = measure(dir / "plane.iso", points);
  for (const ViewVisibility& v : m.visibility.views) EXPECT_EQ(v.seenThrough, 0u);
  EXPECT_LT(m.visibility.depthMedian, 0.2);
}

// Measured region by region (a few hundred leaves each, rays clipped to each region's box, so a
// ray finds nothing that lies outside it), the depth errors are the same, and a point seen through
// in the whole file is seen through in its region too.
TEST(Visibility, regionsGiveTheWholeFilesAnswerOrSeeThroughMore) {
  TempDir dir;
  const PointCloud points = scanOf("torus", 30000, true, 0.5);
  BuildOptions small;
  small.chunkNodes = 2000;
  convertToIso(points, dir / "torus.iso", small);
  VisibilityOptions whole, regions;
  whole.pixelSpacings = regions.pixelSpacings = 0.4;  // some points seen through at the outline
  regions.regionLeaves = 300;
  const Measured a = measure(dir / "torus.iso", points, whole);
  const Measured b = measure(dir / "torus.iso", points, regions);
  uint64_t seen = 0;
  for (size_t v = 0; v < a.visibility.views.size(); ++v) {
    const ViewVisibility &x = a.visibility.views[v], &y = b.visibility.views[v];
    EXPECT_LE(x.seenThrough, y.seenThrough) << "view " << v;
    EXPECT_LE(y.seenThrough, x.seenThrough + points.size() / 50) << "view " << v;
    EXPECT_EQ(x.depthMeasured, y.depthMeasured) << "view " << v;
    EXPECT_NEAR(x.depthMedian, y.depthMedian, 1e-6) << "view " << v;
    seen += x.seenThrough;
  }
  EXPECT_GT(seen, 0u);
  EXPECT_TRUE(std::includes(b.visibility.seen.begin(), b.visibility.seen.end(),
                            a.visibility.seen.begin(), a.visibility.seen.end()));
}

}  // namespace
}  // namespace iso::test
