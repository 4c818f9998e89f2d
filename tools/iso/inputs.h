// Reading the point files named on the command line (files and directories) into one cloud.
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "pipeline/base/progress.h"
#include "pipeline/io/point_cloud.h"
#include "pipeline/io/readers.h"

namespace iso::cli {

// What reading found: per file its path, format, points, dropped points and coordinate system
// (ConvertSource::inputs), and notes for the user (the readers' notes prefixed by their file).
struct ReadSummary {
  nlohmann::json inputs = nlohmann::json::array();
  uint64_t nonFiniteDropped = 0;
  double seconds = 0.0;
  std::vector<std::string> notes;  // e.g. normals ignored because not every input has them
};

struct LoadedPoints : ReadSummary {
  PointCloud cloud;
};

// The files to read: each argument itself, or a directory's point files (sorted by name).
// Throws iso::FileError for a missing path or a directory without point files.
std::vector<std::filesystem::path> expandInputs(const std::vector<std::string>& arguments);

// Read every file in order: `begin` learns whether the points carry normals and colors (kept only
// when every file has them), then `add` gets them in batches. Shows progress in points read when
// `progress` is set. With `scalar`, the batches carry that one extra (ReadOptions::keepExtras) and
// nothing else; a file without it is refused before any is read (iso::FileError naming the file
// and the scalars it has).
ReadSummary readPoints(const std::vector<std::filesystem::path>& files, const ReadOptions& options,
                       ProgressReporter* progress,
                       const std::function<void(bool normals, bool colors)>& begin,
                       const std::function<void(const PointCloud&)>& add,
                       const std::string& scalar = "");

// Whether every file has the extra `name` (opening each, reading no point).
bool everyFileHas(const std::vector<std::filesystem::path>& files, const ReadOptions& options,
                  const std::string& name);

// The index of extra `name` among a file's extras; throws iso::FileError naming the file and the
// scalars it has when it has none of that name.
size_t extraIndex(const PointFileInfo& info, const std::string& name);

// Read every file into one cloud.
LoadedPoints loadPoints(const std::vector<std::filesystem::path>& files, const ReadOptions& options,
                        ProgressReporter* progress = nullptr, const std::string& scalar = "");

}  // namespace iso::cli
