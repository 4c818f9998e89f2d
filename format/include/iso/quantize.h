// Quantization of corner attributes (specs/iso-format.md, "AttributeDesc" encodings): signed
// normalized integers, octahedral unit vectors and sRGB colors. Shared by the writer side
// (pipeline) and every reader, so that both sides agree bit for bit.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

namespace iso {

// snorm8: value q / 127, q in [-127, 127]; rounds to nearest, clamps to [-1, 1]. A value's sign is
// kept or becomes zero, never flipped.
inline int8_t encodeSnorm8(float v) {
  const float c = std::isnan(v) ? 0.0f : (v < -1.0f ? -1.0f : (v > 1.0f ? 1.0f : v));
  return static_cast<int8_t>(std::lround(c * 127.0f));
}
inline float decodeSnorm8(int8_t q) { return q < -127 ? -1.0f : float(q) / 127.0f; }

inline int16_t encodeSnorm16(float v) {
  const float c = std::isnan(v) ? 0.0f : (v < -1.0f ? -1.0f : (v > 1.0f ? 1.0f : v));
  return static_cast<int16_t>(std::lround(c * 32767.0f));
}
inline float decodeSnorm16(int16_t q) { return q < -32767 ? -1.0f : float(q) / 32767.0f; }

// Octahedral encoding of unit vectors (Cigolle et al., "A Survey of Efficient Representations for
// Independent Unit Vectors", JCGT 2014) with `bits` bits per component (8 or 12).
std::array<int32_t, 2> encodeOctahedral(const std::array<float, 3>& n, int bits);
std::array<float, 3> decodeOctahedral(const std::array<int32_t, 2>& q, int bits);

// sRGB transfer functions (IEC 61966-2-1): files store sRGB, computations use linear light.
inline float srgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
inline float linearToSrgb(float c) {
  return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}
// An 8-bit sRGB code for a linear value (clamped to [0, 1]), rounded to nearest.
inline uint8_t linearToSrgb8(float c) {
  const float clamped = std::isnan(c) ? 0.0f : (c < 0.0f ? 0.0f : (c > 1.0f ? 1.0f : c));
  return static_cast<uint8_t>(std::lround(linearToSrgb(clamped) * 255.0f));
}
// The linear value of an 8-bit sRGB code (exact table lookup).
float srgb8ToLinear(uint8_t code);

}  // namespace iso
