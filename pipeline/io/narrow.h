// Conversion of decoded doubles to float attributes without undefined behaviour.
#pragma once

#include <cmath>
#include <limits>

namespace iso::io {

// The float nearest to value; values beyond the float range (legal in a double property of a
// hostile file, undefined behaviour for a plain cast) become infinities.
inline float narrowToFloat(double value) {
  constexpr double kMax = std::numeric_limits<float>::max();
  if (value > kMax) return std::numeric_limits<float>::infinity();
  if (value < -kMax) return -std::numeric_limits<float>::infinity();
  return static_cast<float>(value);
}

}  // namespace iso::io
