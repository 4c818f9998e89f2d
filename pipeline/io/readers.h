// Readers of point files: PLY (ASCII, binary little and big endian), XYZ-like text with a column
// spec or guessed columns, LAS 1.0–1.4 (with its coordinate system), LAZ (LASzip-compressed LAS,
// decoded by laz-perf on every core), E57 (every scan, its pose applied), PCD (ascii, binary,
// binary_compressed) and Draco. Gzip-compressed files (.gz) are read transparently, but for LAZ
// and E57, which seek. Readers stream: they hand out points in batches, so memory does not grow
// with the file (except Draco, which decodes a whole file at once).
//
// Errors (unreadable, malformed, truncated, unsupported files) throw iso::FileError naming the file
// and the byte offset (binary formats) or line (text formats). Points with a NaN or infinite
// coordinate are dropped and counted, never returned. A reader is used by one thread at a time.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/io/point_cloud.h"

namespace iso {

struct ReadOptions {
  // Column spec for text files: comma-separated names among x,y,z,nx,ny,nz,r,g,b, "_" (skip) and
  // names of values (letters, digits and _: extras with keepExtras, else skipped), e.g.
  // "x,y,z,_,r,g,b" or "x,y,z,temperature". Set, it also makes openPointFile read a file of any extension as text
  // unless its signature or a PCD header says otherwise. Empty: guessed from the column count of
  // the first (up to 100) rows and, where the count leaves a choice, their values (r,g,b of 0–255
  // have a value above 1, unit normals none) and the extension: 3 = x,y,z; 4 = x,y,z,_;
  // 6 = x,y,z,nx,ny,nz, or x,y,z,r,g,b for such values or a .xyzrgb file (never for .xyzn);
  // 7 = x,y,z,_,r,g,b (Leica PTS) for such values in the last three, else not guessed;
  // 9 = x,y,z,nx,ny,nz,r,g,b, or x,y,z,r,g,b,nx,ny,nz (CloudCompare) when only columns 4–6 hold
  // such values; others are not guessed. A guess of more than 3 columns is said in a note.
  // Colors in text files are 0–255 when any color value of those rows exceeds 1, else 0–1.
  std::string columns;
  // PLY and PCD: carry every scalar property (field) that is not read as a position, normal or
  // color (intensity, confidence, scalar_*, ...) as an extra, in header order. LAS and LAZ:
  // "intensity", "return_number", "classification" and, where the point format has it,
  // "gps_time" (lasExtraNames). E57: the intensity as the extra "intensity" (as stored; NaN where
  // marked invalid). Text files: the columns of the column spec named otherwise than x,y,z,nx,ny,
  // nz,r,g,b,_. Others have none. Off: such properties are skipped at no cost.
  bool keepExtras = false;
};

// The coordinate reference system a point file declares. LAS files hold it in records of user
// "LASF_Projection": the OGC WKT (record 2112) and the GeoTIFF keys (34735, with their ASCII
// parameters in 34737), in VLRs or in LAS 1.4 EVLRs. Text is UTF-8 (other bytes become '?').
struct CoordinateSystem {
  std::string wkt;  // OGC WKT as stored; empty when the file has none
  // ProjectedCSTypeGeoKey (3072), else GeographicTypeGeoKey (2048), else the authority of the
  // WKT's root element (AUTHORITY["EPSG","n"] or ID["EPSG",n]).
  std::optional<uint32_t> epsg;
  std::optional<uint32_t> verticalEpsg;  // VerticalCSTypeGeoKey (4096)
  // A short name: the GeoTIFF citation (PCSCitationGeoKey 3073, else GTCitationGeoKey 1026), else
  // the WKT's first quoted name.
  std::string name;
  std::string source;  // the records it came from, e.g. "VLR LASF_Projection 2112 (OGC WKT)"
};

struct PointFileInfo {
  std::filesystem::path path;
  std::string
      format;  // "ply-ascii", "ply-binary-le", "ply-binary-be", "xyz", "las 1.2 format 2", ...
  std::optional<uint64_t> declaredPoints;  // the header's count, when the format has one
  bool hasNormals = false;
  bool hasColors = false;
  std::vector<std::string> extraNames;  // the extras read() appends (empty unless keepExtras)
  std::optional<CoordinateSystem> crs;  // when the file declares one
  // What the reader decided that a user may want to know (columns guessed, a color coding
  // detected, records ignored), one sentence each.
  std::vector<std::string> notes;
};

struct ReadStats {
  uint64_t pointsRead = 0;        // returned to the caller
  uint64_t droppedNonFinite = 0;  // points with a NaN or infinite coordinate, dropped
};

class PointReader {
 public:
  virtual ~PointReader() = default;
  virtual const PointFileInfo& info() const = 0;
  // Append up to maxPoints points to out (whose attribute vectors match info()'s has* flags, and
  // whose extraNames become info().extraNames: out must be empty or hold earlier reads of this
  // reader); returns how many were appended, 0 at the end of the file.
  virtual size_t read(PointCloud& out, size_t maxPoints) = 0;
  virtual const ReadStats& stats() const = 0;
};

// Open a point file, choosing the reader by content (PLY magic, LAS signature "LASF" — LAZ when
// its point format is marked compressed —, "DRACO", "ASTM-E57"), then by extension (.pcd; .xyz
// .txt .pts .csv .asc .neu .xyzrgb .xyzn as text), then by content again: a PCD header, or text
// (whyNotText in point_readers.h) for a name of another extension, or of any extension with
// ReadOptions::columns. A .laz or .e57 name without its signature is refused saying so; a file of
// no known format with a message naming each format tried and why the text check failed.
std::unique_ptr<PointReader> openPointFile(const std::filesystem::path& path,
                                           const ReadOptions& options = {});

// Read a whole file into memory.
PointCloud readPointFile(const std::filesystem::path& path, const ReadOptions& options = {},
                         ReadStats* stats = nullptr);

}  // namespace iso
