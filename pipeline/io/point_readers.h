// The readers behind openPointFile, one per format, each taking the opened stream.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/readers.h"

namespace iso::io {

std::unique_ptr<PointReader> makePlyReader(InputStream in, const ReadOptions& options);
std::unique_ptr<PointReader> makeLasReader(InputStream in);
std::unique_ptr<PointReader> makeTextReader(InputStream in, const ReadOptions& options);
std::unique_ptr<PointReader> makePcdReader(InputStream in);
// Draco decodes whole buffers: the reader reads the stream and decodes it on opening.
std::unique_ptr<PointReader> makeDracoReader(InputStream in);

// The extension in lower case with its dot, looking through a final ".gz" ("a.PLY.gz" -> ".ply").
std::string lowercaseExtension(const std::filesystem::path& path);

// The LAZ refusal, shared by the LAS reader (compressed point formats) and openPointFile (.laz).
inline constexpr const char* kLazNotSupported =
    "LAZ (compressed LAS) is not supported: decompress it first (for example with laszip or pdal "
    "translate)";

}  // namespace iso::io
