// The readers behind openPointFile, one per format, each taking the opened stream.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/readers.h"

namespace iso::io {

std::unique_ptr<PointReader> makePlyReader(InputStream in, const ReadOptions& options);
std::unique_ptr<PointReader> makeLasReader(InputStream in);
std::unique_ptr<PointReader> makeTextReader(InputStream in, const ReadOptions& options);
std::unique_ptr<PointReader> makePcdReader(InputStream in);
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
// E57 (ASTM E2807): every point cloud of the file's data3D, each with its pose applied.
std::unique_ptr<PointReader> makeE57Reader(InputStream in, const ReadOptions& options);

// The extension in lower case with its dot, looking through a final ".gz" ("a.PLY.gz" -> ".ply").
std::string lowercaseExtension(const std::filesystem::path& path);

// The LAZ refusal, shared by the LAS reader (compressed point formats) and openPointFile (.laz).
// Debian 12 packages no LAZ decoder (no LASzip, PDAL or libLAS).
inline constexpr const char* kLazNotSupported =
    "LAZ (compressed LAS) is not supported: no LAZ decoder is packaged for Debian 12; decompress "
    "it to LAS first, e.g. `pdal translate in.laz out.las` or `laszip -i in.laz -o out.las`";

}  // namespace iso::io
