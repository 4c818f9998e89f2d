// Fast sRGB decoding of integer color codes, shared by the readers.
#pragma once

#include <array>

namespace iso::io {

// Entry c is the linear value of the 16-bit sRGB code c (srgbToLinear(c / 65535)); an 8-bit code v
// is the 16-bit code v * 257. Built once, on first use; thread-safe.
const std::array<float, 65536>& srgb16ToLinearTable();

// Linear value of a color component given as a number `value` on a scale whose full intensity is
// `fullScale` (255 for 8-bit codes, 1 for [0, 1] floats), clamped to [0, 1].
float linearFromSrgbScaled(double value, double fullScale);

}  // namespace iso::io
