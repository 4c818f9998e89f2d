// Light maps (seed thesis 003 §5.3): the irradiance of a scene's lights at every corner of a
// finished file, direct (shadowed, soft under area lights) and after diffuse bounces, traced on the
// CPU against the finished surface and stored in lighting chunks (iso/lighting.h) beside the
// file's other chunks, which stay as they are (specs/pipeline.md §16, "Light maps").
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "iso/format.h"
#include "iso/surface_model.h"
#include "pipeline/base/options.h"

namespace iso {

class Reader;
class Writer;

struct LightBakeStats {
  uint64_t receivers = 0;    // corners of the finest surface lit (once per chunk holding them)
  uint64_t lodCorners = 0;   // level-of-detail corners, which take the irradiance at their
                             // projection onto the finest surface
  uint64_t unprojected = 0;  // corners whose projection failed (p − f·n used)
  uint64_t ownCorners = 0;   // leaves' corners lit as their own leaf's side (overrides)
  // The direct irradiance drawn (interpolated over the corners) against the exact one at points
  // of the zero set, over the mean exact irradiance: RMS, 95th percentile, largest.
  uint64_t errorSamples = 0;
  double errorRms = 0.0, errorP95 = 0.0, errorMax = 0.0;
  uint64_t shadowRays = 0, bounceRays = 0;
  double directSeconds = 0.0, bounceSeconds = 0.0;
  std::array<double, 3> mean{};  // mean irradiance of the receivers
  int bounces = 0, rays = 0;
  nlohmann::json json() const;    // the conversion report's "lighting"
};

// iso::UsageError naming the option for options a bake cannot take (no light, bounces outside 0
// to 16, rays outside 1 to 4096, light samples outside 1 to 1024, a negative or non-finite
// radiance, color or diffuse weight outside [0, 1]).
void validateLightBake(const LightBakeOptions& options);
// The options as the file's metadata lists them ("lighting").
nlohmann::json lightBakeJson(const LightBakeOptions& options);

// The irradiance at p (frame units) with unit normal n on the open side of `surface` (the file's
// frame places the lights), from the lights alone; `seed` jitters the area lights' samples.
std::array<double, 3> directIrradiance(const SurfaceModel& surface, const Vec3& p, const Vec3& n,
                                       const std::vector<BakeLight>& lights, uint64_t seed,
                                       uint64_t* shadowRays = nullptr);

// The header of a file with lighting chunks: `in`'s, at this format version.
FileHeader withLighting(FileHeader header);

// Copy `in` to `out` (whose header is withLighting(in's)): every chunk byte for byte except the
// lighting chunks `in` has, which are dropped (they must be its last chunks: iso::FileError
// otherwise), then a lighting chunk for each surface chunk. Deterministic: the bytes do not depend
// on the number of threads.
LightBakeStats bakeLighting(const Reader& in, Writer& out, const LightBakeOptions& options);

}  // namespace iso
