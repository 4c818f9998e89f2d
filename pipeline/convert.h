// Points to an .iso file: the in-core conversion driver over the stages of pipeline/stages.h,
// with its report (per-stage time, points/s, memory, octree shape, sizes, accuracy).
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

#include "io/point_cloud.h"
#include "stages.h"

namespace iso {

// Input that does not define a surface (no points, fewer than 3 distinct ones, all on a line).
class ConvertError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ConvertHooks {
  // Called when a stage ends, with its name and duration.
  std::function<void(const std::string& stage, double seconds)> onStage;
};

// Convert the points into the .iso file at output (written atomically). `inputs` describes where
// the points came from (stored in the metadata with the options and the report). Returns the
// report, which the file's metadata also holds under "report".
nlohmann::json convertToIso(const PointCloud& cloud, const std::filesystem::path& output,
                            const BuildOptions& options, const nlohmann::json& inputs,
                            const ConvertHooks& hooks = {});

// The options as JSON (the file's "parameters").
nlohmann::json optionsJson(const BuildOptions& options);

// Peak resident memory of this process so far, in bytes (VmHWM).
uint64_t peakRssBytes();

}  // namespace iso
