// Reading the point files named on the command line (files and directories) into one cloud.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io/point_cloud.h"
#include "io/readers.h"
#include "progress.h"

namespace iso::cli {

struct LoadedPoints {
  PointCloud cloud;
  nlohmann::json inputs = nlohmann::json::array();  // per file: path, format, points, dropped
  uint64_t nonFiniteDropped = 0;
  double seconds = 0.0;
  std::vector<std::string> notes;  // e.g. normals ignored because not every input has them
};

// The files to read: each argument itself, or a directory's point files (sorted by name).
// Throws iso::FileError for a missing path or a directory without point files.
std::vector<std::filesystem::path> expandInputs(const std::vector<std::string>& arguments);

// Read every file into one cloud. Normals (colors) are kept only when every file has them.
// Shows progress in points read when `progress` is set.
LoadedPoints loadPoints(const std::vector<std::filesystem::path>& files,
                        const ReadOptions& options, ProgressReporter* progress = nullptr);

}  // namespace iso::cli
