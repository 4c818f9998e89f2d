// Octahedral unit vectors (Cigolle et al., JCGT 2014, "oct" with the precise variant: of the four
// codes around the continuous one, keep the one whose decoded vector is closest) and sRGB tables.
#include "iso/quantize.h"

#include <algorithm>

namespace iso {
namespace {

float signNotZero(float v) { return v < 0.0f ? -1.0f : 1.0f; }

std::array<float, 2> toOctahedral(const std::array<float, 3>& n) {
  const float l1 = std::abs(n[0]) + std::abs(n[1]) + std::abs(n[2]);
  if (!(l1 > 0.0f) || !std::isfinite(l1)) return {0.0f, 0.0f};  // no direction: +z
  float x = n[0] / l1, y = n[1] / l1;
  if (n[2] < 0.0f) {
    const float fx = (1.0f - std::abs(y)) * signNotZero(x);
    const float fy = (1.0f - std::abs(x)) * signNotZero(y);
    x = fx;
    y = fy;
  }
  return {x, y};
}

float dot(const std::array<float, 3>& a, const std::array<float, 3>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

}  // namespace

std::array<float, 3> decodeOctahedral(const std::array<int32_t, 2>& q, int bits) {
  const float scale = float((1 << (bits - 1)) - 1);
  const float x = std::clamp(float(q[0]) / scale, -1.0f, 1.0f);
  const float y = std::clamp(float(q[1]) / scale, -1.0f, 1.0f);
  std::array<float, 3> n = {x, y, 1.0f - std::abs(x) - std::abs(y)};
  if (n[2] < 0.0f) {
    n[0] = (1.0f - std::abs(y)) * signNotZero(x);
    n[1] = (1.0f - std::abs(x)) * signNotZero(y);
  }
  const float length = std::sqrt(dot(n, n));
  for (float& c : n) c /= length;
  return n;
}

std::array<int32_t, 2> encodeOctahedral(const std::array<float, 3>& n, int bits) {
  const int32_t limit = (1 << (bits - 1)) - 1;
  const float scale = float(limit);
  const std::array<float, 2> p = toOctahedral(n);
  const float length = std::sqrt(dot(n, n));
  const std::array<float, 3> unit =
      length > 0.0f ? std::array<float, 3>{n[0] / length, n[1] / length, n[2] / length}
                    : std::array<float, 3>{0.0f, 0.0f, 1.0f};
  std::array<int32_t, 2> best{};
  float bestDot = -2.0f;
  const int32_t fx = int32_t(std::floor(p[0] * scale)), fy = int32_t(std::floor(p[1] * scale));
  for (int32_t dx = 0; dx <= 1; ++dx)
    for (int32_t dy = 0; dy <= 1; ++dy) {
      const std::array<int32_t, 2> q = {std::clamp(fx + dx, -limit, limit),
                                        std::clamp(fy + dy, -limit, limit)};
      const float d = dot(decodeOctahedral(q, bits), unit);
      if (d > bestDot) {
        bestDot = d;
        best = q;
      }
    }
  return best;
}

float srgb8ToLinear(uint8_t code) {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[size_t(i)] = srgbToLinear(float(i) / 255.0f);
    return t;
  }();
  return table[code];
}

}  // namespace iso
