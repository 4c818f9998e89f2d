// What `iso bake` and `iso convert --bake-light` share: the bake's options from a scene file
// (its lights, material and the command's --bounces and --bake-rays), and the report's lines.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>

#include "pipeline/base/options.h"

namespace iso::cli {

// The scene file's lights (world units; at least one, else a UsageError naming the file) and its
// material's color and diffuse weight, with `bounces` and `rays`.
LightBakeOptions lightBakeFromScene(const std::string& scene, int bounces, int rays);

// --bounces and --bake-rays on a command (defaults from LightBakeOptions).
void addLightBakeOptions(CLI::App* command, int& bounces, int& rays, CLI::Option* needs);

// The report's "lighting" as lines for people.
void printLightBake(const nlohmann::json& lighting);

}  // namespace iso::cli
