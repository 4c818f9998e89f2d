// LASzip's entropy coding (Amir Said's FastAC: a 32-bit arithmetic coder with adaptive models
// updated periodically), as far as this project codes LAZ itself: the chunk table, which the
// LAZ reader decodes (laz_chunks.cpp), and the test and benchmark writer of LAZ files
// (tests/support/laz_writer.cpp). The points themselves are decoded by laz-perf (laz_decoder.h).
// Symbols are decoded by bisection, which selects the symbol LASzip's lookup tables select.
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>
#include <vector>

namespace iso::io::laz {

inline constexpr uint32_t kMinLength = 0x01000000u;  // below it the interval is renormalized
inline constexpr uint32_t kSymbolShift = 15;  // length bits dropped before a symbol's product
inline constexpr uint32_t kBitShift = 13;     // and before a bit's
inline constexpr uint32_t kBitsHigh = 8;      // corrector bits coded with a model

// An adaptive model of `symbols` symbols.
struct SymbolModel {
  explicit SymbolModel(uint32_t symbols)
      : distribution(symbols), counts(symbols, 1), updateCycle(symbols) {
    update();
    untilUpdate = updateCycle = (symbols + 6) >> 1;
  }
  void update() {
    const auto symbols = uint32_t(counts.size());
    if ((total += updateCycle) > (1u << kSymbolShift)) {
      total = 0;
      for (uint32_t& count : counts) total += (count = (count + 1) >> 1);
    }
    const uint32_t scale = 0x80000000u / total;
    uint32_t sum = 0;
    for (uint32_t k = 0; k < symbols; ++k) {
      distribution[k] = (scale * sum) >> (31 - kSymbolShift);
      sum += counts[k];
    }
    updateCycle = std::min((5 * updateCycle) >> 2, (symbols + 6) << 3);
    untilUpdate = updateCycle;
  }
  std::vector<uint32_t> distribution, counts;
  uint32_t total = 0, updateCycle, untilUpdate = 0;
};

// An adaptive model of a bit.
struct BitModel {
  void update() {
    if ((count += updateCycle) > (1u << kBitShift)) {
      count = (count + 1) >> 1;
      zeros = (zeros + 1) >> 1;
      if (zeros == count) ++count;
    }
    zeroProbability = (zeros * (0x80000000u / count)) >> (31 - kBitShift);
    updateCycle = std::min<uint32_t>((5 * updateCycle) >> 2, 64);
    untilUpdate = updateCycle;
  }
  uint32_t zeroProbability = 1u << (kBitShift - 1), zeros = 1, count = 2;
  uint32_t updateCycle = 4, untilUpdate = 4;
};

// The models of LASzip's integer compressor for `bits`-bit integers (1–32) in `contexts`
// contexts: a corrector (real − predicted, wrapped to the range) is coded as its bit length k,
// then its value within [2^(k−1), 2^k) or its negative, the top 8 bits with a model.
struct IntegerModels {
  IntegerModels(uint32_t bits, uint32_t contexts)
      : range(bits < 32 ? uint64_t{1} << bits : 0),
        minimum(bits < 32 ? -int64_t(range / 2) : std::numeric_limits<int32_t>::min()),
        maximum(bits < 32 ? minimum + int64_t(range) - 1 : std::numeric_limits<int32_t>::max()) {
    const uint32_t corrBits = bits < 32 ? bits : 32;
    for (uint32_t i = 0; i < contexts; ++i) lengths.emplace_back(corrBits + 1);
    for (uint32_t k = 1; k <= corrBits; ++k) values.emplace_back(k <= kBitsHigh ? 1u << k : 256u);
  }
  uint64_t range;  // 0 for 32 bits: no wrapping
  int64_t minimum, maximum;
  std::vector<SymbolModel> lengths;  // per context
  std::vector<SymbolModel> values;   // per bit length k - 1
  BitModel zeroOrOne;
};

// The decoder over a source of bytes: `next()` gives the next byte (0 past the end, where it
// should note the overrun).
template <typename Source>
class ArithmeticDecoder {
 public:
  explicit ArithmeticDecoder(Source& source) : source_(source) {
    for (int i = 0; i < 4; ++i) value_ = (value_ << 8) | source_.next();
  }

  uint32_t decodeSymbol(SymbolModel& m) {
    uint32_t y = length_, x = 0, symbol = 0, n = uint32_t(m.distribution.size());
    length_ >>= kSymbolShift;
    for (uint32_t k = n >> 1; k != symbol; k = (symbol + n) >> 1) {
      const uint32_t z = length_ * m.distribution[k];
      if (z > value_) {
        n = k;
        y = z;
      } else {
        symbol = k;
        x = z;
      }
    }
    value_ -= x;
    length_ = y - x;
    if (length_ < kMinLength) renormalize();
    ++m.counts[symbol];
    if (--m.untilUpdate == 0) m.update();
    return symbol;
  }

  uint32_t decodeBit(BitModel& m) {
    const uint32_t x = m.zeroProbability * (length_ >> kBitShift);
    const uint32_t bit = value_ >= x ? 1 : 0;
    if (bit == 0) {
      length_ = x;
      ++m.zeros;
    } else {
      value_ -= x;
      length_ -= x;
    }
    if (length_ < kMinLength) renormalize();
    if (--m.untilUpdate == 0) m.update();
    return bit;
  }

  uint32_t readBits(uint32_t bits) {
    if (bits > 19) {
      const uint32_t low = readBits(16);
      return (readBits(bits - 16) << 16) | low;
    }
    const uint32_t symbol = value_ / (length_ >>= bits);
    value_ -= length_ * symbol;
    if (length_ < kMinLength) renormalize();
    return symbol;
  }

  // The integer predicted as `predicted` in the given context of the models.
  uint32_t decodeInteger(IntegerModels& m, uint32_t predicted, uint32_t context) {
    int64_t real = int64_t(int32_t(predicted)) + readCorrector(m, context);
    if (m.range != 0) {
      if (real < 0) real += int64_t(m.range);
      if (real >= int64_t(m.range)) real -= int64_t(m.range);
    }
    return uint32_t(real);
  }

 private:
  void renormalize() {
    do {
      value_ = (value_ << 8) | source_.next();
    } while ((length_ <<= 8) < kMinLength);
  }

  int64_t readCorrector(IntegerModels& m, uint32_t context) {
    const uint32_t k = decodeSymbol(m.lengths[context]);
    if (k == 0) return decodeBit(m.zeroOrOne);
    if (k >= 32) return m.minimum;
    int64_t c = decodeSymbol(m.values[k - 1]);
    if (k > kBitsHigh) {
      const uint32_t low = k - kBitsHigh;
      c = (c << low) | readBits(low);
    }
    return c >= (int64_t{1} << (k - 1)) ? c + 1 : c - ((int64_t{1} << k) - 1);
  }

  Source& source_;
  uint32_t value_ = 0, length_ = 0xFFFFFFFFu;
};

}  // namespace iso::io::laz
