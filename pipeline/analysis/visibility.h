// What a person sees of an .iso surface (specs/pipeline.md §18): from far views, through the
// viewer's own tracer (shaders/trace.h on the CPU), the share of the scan's points that are "seen
// through" (their pixel and its 8 neighbours show nothing: every ray there missed the surface), and
// how far along the view the surface is from the points nearest the viewer.
//
// A view is an orthographic projection along a direction (a camera far away): 6 along the axes,
// then random ones. Pixels are square, `pixelSpacings` point spacings wide, on a grid
// anchored at the frame's origin. Each pixel's ray passes through its centre. A point is seen
// through when the rays of its pixel and of the 8 around it all miss the surface; it is seen
// through *inside the outline* when the points' own image has no gap around it (the 3×3 blocks
// of two-spacing cells around it all hold points): a hole where the scan looks solid, rather than
// surface stopping short of the scan's outline or an open boundary.
//
// Depth: along the ray through each point itself, the first crossing of the surface within 3
// spacings before or after the point (whatever lies farther along the ray, in front of the point
// or behind it, is not looked at: a point hidden by other surface is measured against its own);
// the depth error is |depth of that hit − depth of the point|, in spacings. Points with no surface
// within 3 spacings along the view are counted apart (they are also the ones a missing surface
// leaves, and those at an outline where the surface lies a little inside the points).
//
// Threading: runs its rays in parallel (TBB); the result does not depend on the thread count.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <nlohmann/json.hpp>
#include <span>
#include <vector>

#include "iso/format.h"

namespace iso {

class Reader;

struct VisibilityOptions {
  int randomViews = 4;         // views in random directions besides the 6 along the axes
  double pixelSpacings = 1.0;  // the width of a pixel, in point spacings
  uint64_t seed = 1;           // of the random views
  // The points are measured region by region, each region a cell of the coarsest level whose
  // cells hold about this many leaves, traced in the chunks that meet it (rays clipped to it,
  // widened by 1/16 of its edge): so about that many leaves are decoded at once. A file of fewer
  // leaves is one region, the whole frame. (Clipping can only add seen-through points: a ray that
  // leaves the region would find nothing near the point it passes anyway.)
  uint64_t regionLeaves = 2000000;
};

struct ViewVisibility {
  glm::dvec3 direction{};    // the view direction (world axes), unit
  uint64_t points = 0;       // points measured (those inside the frame)
  uint64_t seenThrough = 0;  // ... whose pixel and its 8 neighbours show nothing
  // ... of which the scan's own points fill those 9 pixels (a hole inside what the points cover,
  // rather than at the edge of their image: an outline, an open boundary)
  uint64_t seenThroughInside = 0;
  uint64_t depthMeasured = 0;  // points with surface within 3 spacings along the view
  uint64_t depthMissed = 0;    // points without
  // |hit − point| along the view for the measured points, in spacings.
  double depthMedian = 0.0, depthP90 = 0.0, depthMax = 0.0;
  double seenThroughFraction() const { return points ? double(seenThrough) / double(points) : 0.0; }
};

struct Visibility {
  std::vector<ViewVisibility> views;
  std::vector<uint32_t> measured;  // the points measured (inside the frame), as input indices
  std::vector<uint32_t> seen;      // the points seen through in some view, as input indices
  double pixelSpacings = 1.0;
  uint64_t rays = 0;  // traced in all
  // Over all views: seen-through points / (points × views), the worst view's fraction, and the
  // depth errors of every view's front points together.
  double seenThroughFraction() const;
  double worstViewFraction() const;
  double depthMedian = 0.0, depthP90 = 0.0;
  nlohmann::json json() const;
};

// The points are in world units, `pointSpacing` too; points outside the frame's cube are left out.
// Throws iso::FileError for a damaged file.
Visibility measureVisibility(const Reader& reader, std::span<const glm::dvec3> points,
                             double pointSpacing, const VisibilityOptions& options = {});

// The view directions: the 6 axis directions (+x, −x, +y, −y, +z, −z), then `random` uniform ones.
std::vector<glm::dvec3> visibilityViews(int random, uint64_t seed);

}  // namespace iso
