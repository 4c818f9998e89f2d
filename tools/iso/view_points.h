// `iso view` of raw scans (--draw image): the point files read, each an object with its spacing
// and normals (the file's, or estimated from its nearest neighbours); a uniform subsample of them
// when they do not fit the GPU memory budget, and previews of what is read so far for a window
// that opens at once.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

#include "pipeline/io/readers.h"
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

// Point files, and .iso files whose kept points are drawn: the level of detail of at most
// maxPoints points. Throws iso::FileError for a file that does not open (the reader's message).
ImageFiles openImageFiles(const std::vector<std::filesystem::path>& files, uint64_t maxPoints);

struct ImageLoad {
  // Points drawn at most: beyond, every k-th point (a uniform subsample; imageBudget).
  uint64_t maxPoints = std::numeric_limits<uint64_t>::max();
  // Called while reading with what has been read so far (at most kPreviewPoints of it, prepared):
  // after the first batch and whenever the points read have doubled since.
  std::function<void(viewer::ImageInputs&&)> preview;
  const std::atomic<bool>* stop = nullptr;  // set: reading ends early (the result is partial)
};

// Reads the files to their ends. Throws iso::FileError for a file that does not read.
viewer::ImageInputs readImageInputs(ImageFiles& files, const ImageLoad& load = {});

}  // namespace iso::cli
