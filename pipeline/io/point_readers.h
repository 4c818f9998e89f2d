// The readers behind openPointFile, one per format, each taking the opened stream.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/las_format.h"
#include "pipeline/io/readers.h"

namespace iso::io {

std::unique_ptr<PointReader> makePlyReader(InputStream in, const ReadOptions& options);
// LAS, or LAZ for a file whose point format is marked compressed.
std::unique_ptr<PointReader> makeLasReader(InputStream in, const ReadOptions& options);
std::unique_ptr<PointReader> makeTextReader(InputStream in, const ReadOptions& options);
std::unique_ptr<PointReader> makePcdReader(InputStream in, bool keepExtras = false);
// Whether the start of a stream (not consumed) is a text point file: after comments, a count
// line and a line of column names, lines of 3 or more numbers, as many on each, separated by
// blanks, commas or semicolons. nullopt when it is; otherwise why not ("line 3: 'abc' is not a
// number").
std::optional<std::string> whyNotText(InputStream& in);
// Whether the start of a stream (not consumed) is a PCD header: a "# .PCD" comment, or VERSION or
// FIELDS as the first keyword.
bool looksLikePcd(InputStream& in);
// Draco decodes whole buffers: the reader reads the stream and decodes it on opening.
std::unique_ptr<PointReader> makeDracoReader(InputStream in);
// LAZ: LAS whose points LASzip compressed (chunked, point formats 0–3 and 6–8), from its read
// header; chunks decoded in parallel by laz-perf (laz_decoder.h).
std::unique_ptr<PointReader> makeLazReader(InputStream in, const LasHeader& header,
                                           const ReadOptions& options);
// E57 (ASTM E2807): every point cloud of the file's data3D, each with its pose applied.
std::unique_ptr<PointReader> makeE57Reader(InputStream in, const ReadOptions& options);

// The extension in lower case with its dot, looking through a final ".gz" ("a.PLY.gz" -> ".ply").
std::string lowercaseExtension(const std::filesystem::path& path);


}  // namespace iso::io
