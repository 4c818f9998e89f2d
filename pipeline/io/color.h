// sRGB transfer functions (IEC 61966-2-1): inputs store sRGB, computations use linear light.
#pragma once

#include <cmath>
#include <cstdint>

namespace iso {

inline float srgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

inline float linearToSrgb(float c) {
  return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

// An 8-bit sRGB code for a linear value in [0, 1] (clamped), rounded to nearest.
inline uint8_t linearToSrgb8(float c) {
  const float s = linearToSrgb(c < 0.0f ? 0.0f : (c > 1.0f ? 1.0f : c));
  return static_cast<uint8_t>(std::lround(s * 255.0f));
}

}  // namespace iso
