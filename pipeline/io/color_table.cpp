#include "pipeline/io/color_table.h"

#include <array>
#include <cmath>

#include "pipeline/io/color.h"

namespace iso::io {
namespace {

// One std::pow per code instead of one per point keeps color decoding off the readers' profiles.
std::array<float, 65536> makeTable() {
  std::array<float, 65536> table{};
  for (size_t c = 0; c < table.size(); ++c) table[c] = srgbToLinear(float(c) / 65535.0f);
  return table;
}

}  // namespace

const std::array<float, 65536>& srgb16ToLinearTable() {
  static const std::array<float, 65536> table = makeTable();
  return table;
}

float linearFromSrgbScaled(double value, double fullScale) {
  const double unit = value / fullScale;
  if (!(unit > 0.0)) return 0.0f;  // also NaN
  if (unit >= 1.0) return 1.0f;
  return srgbToLinear(static_cast<float>(unit));
}

}  // namespace iso::io
