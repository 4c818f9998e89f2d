// Random numbers that are the same on every machine and standard library.
//
// std::mt19937_64 is specified bit for bit by the standard, but the std:: distributions are not, so
// every shape and the scan generator draw through these functions instead.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

namespace iso {

// A uniform double in [0, 1): the top 53 bits of one draw, scaled by 2^-53.
inline double uniform01(std::mt19937_64& rng) { return double(rng() >> 11) * 0x1.0p-53; }

// A standard normal deviate by the Box–Muller transform (Box and Muller 1958); 1 - u keeps the
// logarithm's argument in (0, 1].
inline double standardNormal(std::mt19937_64& rng) {
  const double u = 1.0 - uniform01(rng);
  const double v = uniform01(rng);
  return std::sqrt(-2.0 * std::log(u)) * std::cos(2.0 * std::numbers::pi * v);
}

// SplitMix64's finalizer (Steele, Lea and Flood 2014): a bijective mix of 64 bits, used to derive
// independent seeds from (seed, stream index).
inline uint64_t mixBits(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

}  // namespace iso
