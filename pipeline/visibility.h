// What a person sees of an .iso surface (specs/pipeline.md §18): from far views, through the
// viewer's own tracer (shaders/trace.h on the CPU), the share of the scan's points that are "seen
// through" (their pixel and its 8 neighbours show nothing: every ray there missed the surface), and
// how far along the view the surface is from the points nearest the viewer.
//
// A view is an orthographic projection along a direction (a camera far away): 6 along the axes,
// then random ones. Pixels are square, `pixelSpacings` mean point spacings wide, on a grid
// anchored at the frame's origin. Each pixel's ray passes through its centre. A point is *front*
// when no point within a spacing of it across the view (in the pixels that far) is nearer the
// viewer by more than a spacing; its depth error is |depth of the hit − depth of the point| along
// the ray through the point itself, in spacings.
//
// A point is also counted as seen through *inside* when the scan's own points fill its 3×3 pixels:
// a hole where the points look solid, rather than surface that stops short of the outline.
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
  int randomViews = 4;          // views in random directions besides the 6 along the axes
  double pixelSpacings = 1.0;   // the width of a pixel, in mean point spacings
  uint64_t seed = 1;            // of the random views
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
  uint64_t front = 0;        // front points
  uint64_t frontMissed = 0;  // ... whose own ray hits nothing (no depth error for them)
  // |hit − point| along the view for the front points that hit, in mean spacings.
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

// The points are in world units, `meanSpacing` too; points outside the frame's cube are left out.
// Throws iso::FileError for a damaged file.
Visibility measureVisibility(const Reader& reader, std::span<const glm::dvec3> points,
                             double meanSpacing, const VisibilityOptions& options = {});

// The view directions: the 6 axis directions (+x, −x, +y, −y, +z, −z), then `random` uniform ones.
std::vector<glm::dvec3> visibilityViews(int random, uint64_t seed);

}  // namespace iso
