// LAS output of points (ASPRS LAS 1.2): what tools that read only LAS (point converters, GIS)
// need from a synthetic scan. Debian packages no LAS library (neither LASlib nor PDAL), so the
// few fixed fields are written here.
#pragma once

#include <filesystem>

#include "pipeline/io/point_cloud.h"

namespace iso {

// Write points to a LAS 1.2 file, atomically: point data format 0, or 2 with colors (16-bit,
// the 8-bit sRGB code times 257). Normals are not written (LAS 1.2 has no field for them).
// Positions are integers times a power-of-ten scale (the finest whose integers hold the extent)
// plus an offset: exact to half the scale. Throws iso::FileError on failure, and when there are
// more points than LAS 1.2 can count (2^32 - 1).
void writeLas(const std::filesystem::path& path, const PointCloud& points);

}  // namespace iso
