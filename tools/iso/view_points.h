// `iso view` of raw scans (--draw image): the point files read whole, each an object with its
// spacing and normals (the file's, or estimated from its nearest neighbours).
#pragma once

#include <filesystem>
#include <vector>

#include "viewer/image_view.h"

namespace iso::cli {

// Throws iso::FileError for a file that does not read (the reader's message).
viewer::ImageInputs loadImageInputs(const std::vector<std::filesystem::path>& files);

}  // namespace iso::cli
