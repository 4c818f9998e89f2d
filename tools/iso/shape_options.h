// Shape options shared by `iso gen` and `iso eval`, so both describe the same truth the same way.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "iso/error.h"
#include "pipeline/geom/shape.h"

namespace iso::cli {

struct ShapeOptions {
  ShapeParams params;
  std::string center = "0,0,0";
  std::string offset = "0,0,0";  // added to every position (gen) or to the truth (eval)
  std::string rotate = "0,0,0";  // degrees about x, y, z (analytic shapes)
  std::string mesh;              // a PLY mesh instead of an analytic shape
};

void addShapeOptions(CLI::App& command, ShapeOptions& options);

// "x,y,z" → vector; throws UsageError naming the option.
glm::dvec3 parseVector(const std::string& text, const char* option);

// The truth the options describe (the offset included).
std::unique_ptr<Shape> makeTruth(const ShapeOptions& options);

}  // namespace iso::cli
