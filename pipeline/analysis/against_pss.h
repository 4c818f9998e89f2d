// The ISO surface against the point set surface of the points it was made from (`iso eval
// FILE.iso --against-pss`): both ray traced from the same views on the CPU (the ISO by the
// viewer's tracer at its finest level, the PSS in its exact mode, tracer/pss.h), compared pixel
// by pixel: silhouettes, depths, normals, the same shading's PSNR, and each one's rays/s.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>
#include <nlohmann/json.hpp>

#include "iso/reader.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

struct AgainstPssOptions {
  int size = 256;  // pixels across each view
  // When set, called for each view (0 to 5: +x, -x, +y, -y, +z, -z) with the shading of the ISO
  // and of the PSS (8-bit gray, size × size, rows from the top).
  std::function<void(int view, const std::vector<uint8_t>& iso, const std::vector<uint8_t>& pss)>
      pictures;
};

// The six views along the axes, framing `points` (the file's kept points, with their normals; at
// least one). Throws iso::FileError for a file that holds no surface.
nlohmann::json evaluateAgainstPss(const Reader& reader, PointCloud points, double spacing,
                                  const AgainstPssOptions& options = {});

}  // namespace iso
