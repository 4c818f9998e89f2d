// The bytestream of one prototype field under E57's bitpack codec (ASTM E2807 section 9.9.3.3
// "Bitpack codec"): its values follow one another as one little-endian bit stream (the first
// value in the lowest bits of the first byte), continued from each data packet to the next.
// Floats take 32 or 64 bits (IEEE, little endian); integers take value - minimum in
// E57Field::bitWidth() bits, none when minimum == maximum.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "pipeline/io/e57_xml.h"

namespace iso::io {

// The bytes of a field's bytestream that arrived and are not decoded yet. Memory: at most twice
// the pending bytes (which the caller bounds) and the last buffer appended.
class E57ByteStream {
 public:
  explicit E57ByteStream(const E57Field& field);

  uint32_t bitWidth() const { return width_; }
  // Append the field's buffer of a data packet.
  void append(std::span<const std::byte> bytes);
  // Whole values that the pending bytes hold (for a 0-bit field, as many as asked for).
  uint64_t availableValues() const;
  size_t pendingBytes() const { return size_ - static_cast<size_t>(bitPosition_ / 8); }
  // Decode the next `count` values (at most availableValues()) into out: floats as they are,
  // integers as minimum + raw, scaled integers as (minimum + raw) * scale + offset.
  void decode(size_t count, double* out);
  // Pass over the next `count` values (at most availableValues()).
  void skip(size_t count) { bitPosition_ += uint64_t(count) * width_; }

 private:
  void decodeIntegers(size_t count, double* out) const;

  E57Encoding encoding_;
  uint32_t width_;
  int64_t minimum_;
  double scale_;
  double offset_;
  // Decoded bytes, the pending bytes from bitPosition_ / 8 to size_, then zeros, so that a value
  // can be loaded with two 8-byte reads wherever it starts.
  std::vector<std::byte> bytes_;
  size_t size_ = 0;
  uint64_t bitPosition_ = 0;  // the first bit not decoded
};

}  // namespace iso::io
