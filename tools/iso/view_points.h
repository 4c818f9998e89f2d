// `iso view` of raw scans (--draw image): the point files read and held in memory (PointStore),
// and the points drawn, each file an object with its spacing and normals (the file's, or
// estimated from its nearest neighbours): all of them when they fit the GPU memory budget,
// beyond it those a view needs; and previews of what is read so far for a window that opens at
// once.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

#include "pipeline/io/readers.h"
#include "pipeline/points/point_store.h"
#include "viewer/image_view.h"

namespace iso::cli {

// Previews hold at most this many points (prepared in a fraction of a second).
inline constexpr uint64_t kPreviewPoints = 300'000;

// The point files of a view, opened (their headers read and checked).
struct ImageFiles {
  std::vector<std::filesystem::path> paths;
  std::vector<std::unique_ptr<PointReader>> readers;
  std::optional<uint64_t> declaredPoints;  // all files' together, when every header says
};

// Whether a file is an .iso file (its header's magic), not a raw scan.
bool isIsoFile(const std::filesystem::path& path);

// Points held in memory at most (a quarter of the machine's memory, at 40 bytes a point, at most
// 2³² − 1): files with more are read every k-th point.
uint64_t hostPointBudget();

// Point files, and .iso files whose kept points are drawn: the level of detail of at most
// maxPoints points (hostPointBudget). Throws iso::FileError for a file that does not open (the
// reader's message).
ImageFiles openImageFiles(const std::vector<std::filesystem::path>& files, uint64_t maxPoints);

struct ImageLoad {
  // Points drawn at most (imageBudget): beyond, those a view needs, or a uniform subsample.
  uint64_t maxPoints = std::numeric_limits<uint64_t>::max();
  // Points held in memory at most: beyond, every k-th point read.
  uint64_t hostPoints = hostPointBudget();
  // Called while reading with what has been read so far (at most kPreviewPoints of it, prepared):
  // after the first batch and whenever the points read have doubled since.
  std::function<void(viewer::ImageInputs&&)> preview;
  const std::atomic<bool>* stop = nullptr;  // set: reading ends early (the result is partial)
};

// The files read: their points (all of them, or every k-th beyond load.hostPoints).
struct ImagePoints {
  PointStore store;
  uint64_t pointsRead = 0;
  double readSeconds = 0.0;
  viewer::ImageInputs frame;  // the bounds, origin, up and names, no objects (sceneCamera)
};

// Reads the files to their ends. Throws iso::FileError for a file that does not read.
ImagePoints readImagePoints(ImageFiles& files, const ImageLoad& load = {});

// The points to draw, prepared: all of them when they fit maxPoints; beyond it, those `view`
// needs (PointStore::forView), or a uniform subsample without a view.
viewer::ImageInputs imageInputs(const ImagePoints& points, uint64_t maxPoints,
                                const PointView* view = nullptr);
// What `camera` sees at width × height pixels (world units).
PointView pointViewOf(const viewer::Camera& camera, uint32_t width, uint32_t height);

// readImagePoints, then imageInputs without a view.
viewer::ImageInputs readImageInputs(ImageFiles& files, const ImageLoad& load = {});

}  // namespace iso::cli
