// Helpers of the pipeline tests: scans of shapes with a known answer, converted and measured.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/analysis/evaluate.h"
#include "pipeline/base/options.h"
#include "pipeline/convert/convert.h"
#include "pipeline/geom/generate.h"
#include "pipeline/geom/shape.h"
#include "pipeline/octree/field.h"
#include "tests/support/support.h"

namespace iso::test {

// A scan of an analytic shape.
PointCloud scanOf(const std::string& shape, uint64_t count, bool normals = true, double noise = 0.0,
                  uint64_t seed = 1);
PointCloud scanOf(const ShapeParams& shape, uint64_t count, bool normals = true,
                  double noise = 0.0, uint64_t seed = 1);

// A shape turned out of the axes, 25° about x and 15° about y: a square along the axes is a line
// seen from 4 of the axis views.
ShapeParams turnedShape(const std::string& name);

struct Converted {
  nlohmann::json report;
  SurfaceModel surface;
};

// Convert points to path (quietly) and load the written surface.
Converted convertAndLoad(const PointCloud& points, const std::filesystem::path& path,
                         const BuildOptions& options = {});

// Two closures agree entry for entry: the corners' coarsest levels and values (bit for bit), the
// corners in use, and the hanging corners in the same order with the same sources (failures name
// `what`).
void expectSameClosure(const Closure& a, const Closure& b, const std::string& what);

// evaluateAgainstShape with the report's spacing.
nlohmann::json evaluate(const Converted& converted, const Shape& truth, uint64_t rays = 20000);

// Write an 8-bit binary PPM (rows from the top, RGB bytes), an image any OpenImageIO reads.
void writePpm(const std::filesystem::path& path, uint32_t width, uint32_t height,
              const std::vector<uint8_t>& rgb);

// A width × height image of random colors (a texture with detail at every texel).
std::vector<uint8_t> randomImage(uint32_t width, uint32_t height, uint32_t seed);

}  // namespace iso::test
