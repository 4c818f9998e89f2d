// Decoding E57 bitpack bytestreams in batches (ASTM E2807 9.9.3.3): one loop per encoding, so
// that a batch of a field's values costs a few instructions each.
#include "pipeline/io/e57_bitpack.h"

#include <algorithm>
#include <cstring>
#include <limits>

#include "iso/check.h"
#include "pipeline/io/little_endian.h"

namespace iso::io {
namespace {

// Zero bytes kept after the pending ones: a value of up to 64 bits starting at any bit of the last
// pending byte is read with two 8-byte loads.
constexpr size_t kPadding = 16;

// The raw value of `width` bits that starts at bit `bit` of `data`. Narrow values (width + 7 <= 64)
// come from one 8-byte load, wide ones from two.
template <bool kIsWide>
uint64_t rawValue(const std::byte* data, uint64_t bit, uint32_t width, uint64_t mask) {
  const std::byte* p = data + bit / 8;
  const unsigned shift = static_cast<unsigned>(bit % 8);
  uint64_t value = loadLittleEndian<uint64_t>(p) >> shift;
  if constexpr (kIsWide) {
    if (shift != 0 && width + shift > 64)
      value |= loadLittleEndian<uint64_t>(p + 8) << (64 - shift);
  }
  return value & mask;
}

template <bool kIsWide>
void unpack(const std::byte* data, uint64_t bit, uint32_t width, int64_t minimum, double scale,
            double offset, size_t count, double* out) {
  const uint64_t mask =
      width == 64 ? std::numeric_limits<uint64_t>::max() : (uint64_t{1} << width) - 1;
  for (size_t i = 0; i < count; ++i, bit += width) {
    // minimum + raw lies in [minimum, maximum]: the unsigned sum wraps to the right integer.
    const auto value =
        static_cast<int64_t>(uint64_t(minimum) + rawValue<kIsWide>(data, bit, width, mask));
    out[i] = double(value) * scale + offset;
  }
}

}  // namespace

E57ByteStream::E57ByteStream(const E57Field& field)
    : encoding_(field.encoding),
      width_(field.bitWidth()),
      minimum_(field.minimum),
      scale_(field.encoding == E57Encoding::kScaledInteger ? field.scale : 1.0),
      offset_(field.encoding == E57Encoding::kScaledInteger ? field.offset : 0.0),
      bytes_(kPadding) {}

void E57ByteStream::append(std::span<const std::byte> bytes) {
  if (bytes.empty()) return;
  // Drop the decoded whole bytes once they are as many as the pending ones: each byte is then
  // moved a bounded number of times on average, and the buffer stays under twice what is pending.
  const size_t decoded = static_cast<size_t>(bitPosition_ / 8);
  if (decoded > 0 && decoded >= size_ - decoded) {
    std::memmove(bytes_.data(), bytes_.data() + decoded, size_ - decoded);
    size_ -= decoded;
    bitPosition_ %= 8;
  }
  if (bytes_.size() < size_ + bytes.size() + kPadding)
    bytes_.resize(size_ + bytes.size() + kPadding);
  std::memcpy(bytes_.data() + size_, bytes.data(), bytes.size());
  size_ += bytes.size();
  std::memset(bytes_.data() + size_, 0, kPadding);
}

uint64_t E57ByteStream::availableValues() const {
  if (width_ == 0) return std::numeric_limits<uint64_t>::max();
  return (uint64_t(size_) * 8 - bitPosition_) / width_;
}

void E57ByteStream::decode(size_t count, double* out) {
  ISO_DCHECK(count <= availableValues());
  const std::byte* first = bytes_.data() + bitPosition_ / 8;  // floats start on whole bytes
  switch (encoding_) {
    case E57Encoding::kSingle:
      for (size_t i = 0; i < count; ++i) out[i] = loadLittleEndian<float>(first + 4 * i);
      break;
    case E57Encoding::kDouble:
      for (size_t i = 0; i < count; ++i) out[i] = loadLittleEndian<double>(first + 8 * i);
      break;
    case E57Encoding::kInteger:
    case E57Encoding::kScaledInteger:
      decodeIntegers(count, out);
      break;
  }
  skip(count);
}

void E57ByteStream::decodeIntegers(size_t count, double* out) const {
  if (width_ == 0) {
    const double value = double(minimum_) * scale_ + offset_;
    std::fill(out, out + count, value);
  } else if (width_ + 7 <= 64) {
    unpack<false>(bytes_.data(), bitPosition_, width_, minimum_, scale_, offset_, count, out);
  } else {
    unpack<true>(bytes_.data(), bitPosition_, width_, minimum_, scale_, offset_, count, out);
  }
}

}  // namespace iso::io
