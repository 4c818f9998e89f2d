// The ISO surface against the point set surface of the points it was made from (`iso eval
// FILE.iso --against-pss`): both ray traced from the same views on the CPU (the ISO by the
// viewer's tracer at its finest level, the PSS in its exact mode, viewer/pss.h), compared pixel
// by pixel: silhouettes, depths, normals, the same shading's PSNR, and each one's rays/s.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "iso/reader.h"

namespace iso {

struct AgainstPssOptions {
  int size = 256;  // pixels across each view
};

// The six views along the axes, framing the kept points. Throws iso::FileError for a file that
// keeps no points (iso convert --keep-points) or holds no surface.
nlohmann::json evaluateAgainstPss(const Reader& reader, const std::string& file, double spacing,
                                  const AgainstPssOptions& options = {});

}  // namespace iso
