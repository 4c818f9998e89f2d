#include "tests/support/laz_writer.h"

#include <fmt/format.h>

#include <array>
#include <cstring>
#include <fstream>
#include <memory>
#include <optional>
#include <vector>

#include "iso/error.h"
#include "pipeline/io/input_stream.h"
#include "pipeline/io/las_format.h"
#include "pipeline/io/laz_coder.h"

namespace iso::bench {
namespace {

using io::laz::BitModel;
using io::laz::IntegerModels;
using io::laz::kBitShift;
using io::laz::kBitsHigh;
using io::laz::kMinLength;
using io::laz::kSymbolShift;
using io::laz::SymbolModel;

constexpr size_t kPoint10Bytes = 20;

// The encoder matching io::laz::ArithmeticDecoder, writing to a byte vector.
class ArithmeticEncoder {
 public:
  explicit ArithmeticEncoder(std::vector<uint8_t>& out) : out_(out), first_(out.size()) {}

  void encodeSymbol(SymbolModel& m, uint32_t symbol) {
    const uint32_t before = base_;
    if (symbol == m.distribution.size() - 1) {
      const uint32_t x = m.distribution[symbol] * (length_ >> kSymbolShift);
      base_ += x;
      length_ -= x;
    } else {
      const uint32_t x = m.distribution[symbol] * (length_ >>= kSymbolShift);
      base_ += x;
      length_ = m.distribution[symbol + 1] * length_ - x;
    }
    settle(before);
    ++m.counts[symbol];
    if (--m.untilUpdate == 0) m.update();
  }

  void encodeBit(BitModel& m, uint32_t bit) {
    const uint32_t x = m.zeroProbability * (length_ >> kBitShift);
    const uint32_t before = base_;
    if (bit == 0) {
      length_ = x;
      ++m.zeros;
    } else {
      base_ += x;
      length_ -= x;
    }
    settle(before);
    if (--m.untilUpdate == 0) m.update();
  }

  void writeBits(uint32_t bits, uint32_t value) {
    if (bits > 19) {
      writeBits(16, value & 0xFFFF);
      value >>= 16;
      bits -= 16;
    }
    const uint32_t before = base_;
    base_ += value * (length_ >>= bits);
    settle(before);
  }

  // The integer `real` predicted as `predicted`; returns the corrector's bit length k.
  uint32_t encodeInteger(IntegerModels& m, int32_t predicted, int32_t real, uint32_t context) {
    int64_t c = m.range == 0 ? int64_t(int32_t(uint32_t(real) - uint32_t(predicted)))
                             : int64_t(real) - predicted;
    if (m.range != 0 && c < m.minimum) c += int64_t(m.range);
    if (m.range != 0 && c > m.maximum) c -= int64_t(m.range);
    uint64_t magnitude = c <= 0 ? uint64_t(-c) : uint64_t(c - 1);
    uint32_t k = 0;
    for (; magnitude != 0; ++k) magnitude >>= 1;
    encodeSymbol(m.lengths[context], k);
    if (k == 0) {
      encodeBit(m.zeroOrOne, uint32_t(c));
    } else if (k < 32) {
      c = c < 0 ? c + ((int64_t{1} << k) - 1) : c - 1;
      if (k <= kBitsHigh) {
        encodeSymbol(m.values[k - 1], uint32_t(c));
      } else {
        const uint32_t low = k - kBitsHigh;
        encodeSymbol(m.values[k - 1], uint32_t(c >> low));
        writeBits(low, uint32_t(c & ((int64_t{1} << low) - 1)));
      }
    }
    return k;
  }

  // Flush the interval: the decoder reads up to 4 bytes ahead, which are all there.
  void done() {
    const uint32_t before = base_;
    const bool isAnotherByte = length_ > 2 * kMinLength;
    if (isAnotherByte) {
      base_ += kMinLength;
      length_ = kMinLength >> 1;
    } else {
      base_ += kMinLength >> 1;
      length_ = kMinLength >> 9;
    }
    if (before > base_) propagateCarry();
    renormalize();
    out_.insert(out_.end(), isAnotherByte ? 3 : 2, 0);
  }

 private:
  void settle(uint32_t before) {
    if (before > base_) propagateCarry();
    if (length_ < kMinLength) renormalize();
  }
  void propagateCarry() {
    for (size_t i = out_.size(); i-- > first_;) {
      if (out_[i] != 0xFF) {
        ++out_[i];
        return;
      }
      out_[i] = 0;
    }
  }
  void renormalize() {
    do {
      out_.push_back(uint8_t(base_ >> 24));
      base_ <<= 8;
    } while ((length_ <<= 8) < kMinLength);
  }

  std::vector<uint8_t>& out_;
  size_t first_;
  uint32_t base_ = 0, length_ = 0xFFFFFFFFu;
};

// LASzip's running "median" of the last five coordinate differences (StreamingMedian5): an
// estimate kept in five sorted slots, shifted up or down by each new value.
class Median5 {
 public:
  int32_t get() const { return v_[2]; }
  void add(int32_t x) {
    if (isHigh_) {
      if (x < v_[2]) {
        v_[4] = v_[3];
        v_[3] = v_[2];
        if (x < v_[0]) {
          v_[2] = v_[1];
          v_[1] = v_[0];
          v_[0] = x;
        } else if (x < v_[1]) {
          v_[2] = v_[1];
          v_[1] = x;
        } else {
          v_[2] = x;
        }
      } else {
        if (x < v_[3]) {
          v_[4] = v_[3];
          v_[3] = x;
        } else {
          v_[4] = x;
        }
        isHigh_ = false;
      }
    } else {
      if (v_[2] < x) {
        v_[0] = v_[1];
        v_[1] = v_[2];
        if (v_[4] < x) {
          v_[2] = v_[3];
          v_[3] = v_[4];
          v_[4] = x;
        } else if (v_[3] < x) {
          v_[2] = v_[3];
          v_[3] = x;
        } else {
          v_[2] = x;
        }
      } else {
        if (v_[1] < x) {
          v_[0] = v_[1];
          v_[1] = x;
        } else {
          v_[0] = x;
        }
        isHigh_ = true;
      }
    }
  }

 private:
  std::array<int32_t, 5> v_{};
  bool isHigh_ = true;
};

// LASzip's contexts of a return: by (number of returns, return number), each 0–7.
constexpr uint8_t kReturnMap[8][8] = {
    {15, 14, 13, 12, 11, 10, 9, 8},  {14, 0, 1, 3, 6, 10, 10, 9},
    {13, 1, 2, 4, 7, 11, 11, 10},    {12, 3, 4, 5, 8, 12, 12, 11},
    {11, 6, 7, 8, 9, 13, 13, 12},    {10, 10, 11, 12, 13, 14, 14, 13},
    {9, 10, 11, 12, 13, 14, 15, 14}, {8, 9, 10, 11, 12, 13, 14, 15}};
constexpr uint8_t kReturnLevel[8][8] = {{0, 1, 2, 3, 4, 5, 6, 7}, {1, 0, 1, 2, 3, 4, 5, 6},
                                        {2, 1, 0, 1, 2, 3, 4, 5}, {3, 2, 1, 0, 1, 2, 3, 4},
                                        {4, 3, 2, 1, 0, 1, 2, 3}, {5, 4, 3, 2, 1, 0, 1, 2},
                                        {6, 5, 4, 3, 2, 1, 0, 1}, {7, 6, 5, 4, 3, 2, 1, 0}};

struct Point10 {
  int32_t x, y, z;
  uint16_t intensity;
  uint8_t bits, classification;
  int8_t scanAngle;
  uint8_t userData;
  uint16_t source;
};

Point10 loadPoint(const uint8_t* p) {
  Point10 q;
  std::memcpy(&q.x, p, 4);
  std::memcpy(&q.y, p + 4, 4);
  std::memcpy(&q.z, p + 8, 4);
  std::memcpy(&q.intensity, p + 12, 2);
  q.bits = p[14];
  q.classification = p[15];
  q.scanAngle = int8_t(p[16]);
  q.userData = p[17];
  std::memcpy(&q.source, p + 18, 2);
  return q;
}

// The POINT10 (version 2) compressor of one chunk.
class Point10Encoder {
 public:
  explicit Point10Encoder(std::vector<uint8_t>& out) : out_(out) {}

  void add(const uint8_t* record) {
    const Point10 p = loadPoint(record);
    if (!encoder_) {  // the first point of a chunk is stored as it is, the others coded after it
      out_.insert(out_.end(), record, record + kPoint10Bytes);
      encoder_.emplace(out_);
      last_ = p;
      return;
    }
    ArithmeticEncoder& encoder = *encoder_;
    const uint32_t r = p.bits & 7, n = (p.bits >> 3) & 7;
    const uint32_t m = kReturnMap[n][r], l = kReturnLevel[n][r];
    const uint32_t changed =
        (uint32_t(p.bits != last_.bits) << 5) | (uint32_t(p.intensity != lastIntensity_[m]) << 4) |
        (uint32_t(p.classification != last_.classification) << 3) |
        (uint32_t(p.scanAngle != last_.scanAngle) << 2) |
        (uint32_t(p.userData != last_.userData) << 1) | uint32_t(p.source != last_.source);
    encoder.encodeSymbol(changedValues_, changed);
    if (changed & 32) encoder.encodeSymbol(model(bitByte_, last_.bits), p.bits);
    if (changed & 16) {
      encoder.encodeInteger(intensity_, lastIntensity_[m], p.intensity, m < 3 ? m : 3);
      lastIntensity_[m] = p.intensity;
    }
    if (changed & 8)
      encoder.encodeSymbol(model(classification_, last_.classification), p.classification);
    if (changed & 4)
      encoder.encodeSymbol(scanAngle_[(p.bits >> 6) & 1], uint8_t(p.scanAngle - last_.scanAngle));
    if (changed & 2) encoder.encodeSymbol(model(userData_, last_.userData), p.userData);
    if (changed & 1) encoder.encodeInteger(source_, last_.source, p.source, 0);
    const int32_t dx = int32_t(uint32_t(p.x) - uint32_t(last_.x));
    const uint32_t kx = encoder.encodeInteger(dx_, medianX_[m].get(), dx, n == 1);
    medianX_[m].add(dx);
    const int32_t dy = int32_t(uint32_t(p.y) - uint32_t(last_.y));
    const uint32_t ky =
        encoder.encodeInteger(dy_, medianY_[m].get(), dy, (n == 1) + (kx < 20 ? kx & ~1u : 20));
    medianY_[m].add(dy);
    const uint32_t kz = (kx + ky) / 2;
    encoder.encodeInteger(z_, lastHeight_[l], p.z, (n == 1) + (kz < 18 ? kz & ~1u : 18));
    lastHeight_[l] = p.z;
    last_ = p;
  }

  void done() {
    if (encoder_) encoder_->done();
  }

 private:
  static SymbolModel& model(std::array<std::unique_ptr<SymbolModel>, 256>& models, uint8_t i) {
    if (!models[i]) models[i] = std::make_unique<SymbolModel>(256);
    return *models[i];
  }

  std::vector<uint8_t>& out_;
  std::optional<ArithmeticEncoder> encoder_;
  Point10 last_{};
  SymbolModel changedValues_{64};
  std::array<std::unique_ptr<SymbolModel>, 256> bitByte_, classification_, userData_;
  std::array<SymbolModel, 2> scanAngle_{SymbolModel(256), SymbolModel(256)};
  IntegerModels intensity_{16, 4}, source_{16, 1}, dx_{32, 2}, dy_{32, 22}, z_{32, 20};
  std::array<uint16_t, 16> lastIntensity_{};
  std::array<int32_t, 8> lastHeight_{};
  std::array<Median5, 16> medianX_, medianY_;
};

template <typename T>
void store(std::vector<uint8_t>& bytes, size_t at, T value) {
  std::memcpy(bytes.data() + at, &value, sizeof value);
}
template <typename T>
void append(std::vector<uint8_t>& bytes, T value) {
  bytes.resize(bytes.size() + sizeof value);
  store(bytes, bytes.size() - sizeof value, value);
}

// The LASzip VLR: header (user "laszip encoded", record 22204) and payload for POINT10 v2.
std::vector<uint8_t> laszipRecord(uint32_t chunkSize) {
  std::vector<uint8_t> r(54, 0);
  std::memcpy(r.data() + 2, "laszip encoded", 14);
  store<uint16_t>(r, 18, 22204);
  store<uint16_t>(r, 20, 34 + 6);
  std::memcpy(r.data() + 22, "iso benchmark", 13);
  append<uint16_t>(r, 2);  // pointwise chunked
  append<uint16_t>(r, 0);  // arithmetic coder
  append<uint8_t>(r, 3);
  append<uint8_t>(r, 4);
  append<uint16_t>(r, 3);
  append<uint32_t>(r, 0);
  append<uint32_t>(r, chunkSize);
  append<int64_t>(r, -1);
  append<int64_t>(r, -1);
  append<uint16_t>(r, 1);
  append<uint16_t>(r, 6);  // POINT10, 20 bytes, version 2
  append<uint16_t>(r, 20);
  append<uint16_t>(r, 2);
  return r;
}

}  // namespace

void writeLazFromLas(const std::filesystem::path& las, const std::filesystem::path& laz,
                     uint32_t chunkSize) {
  io::InputStream in(las);
  const io::LasHeader header = io::readLasHeader(in);
  if (header.isCompressed || header.pointFormat != 0 || header.versionMinor > 3 ||
      header.recordLength != kPoint10Bytes)
    in.failAt(0, "the LAZ writer takes uncompressed LAS 1.0-1.3 of point format 0");
  std::vector<uint8_t> head(header.pointDataOffset);
  if (!in.readExact(head.data(), head.size())) in.fail("file ends before its point data");
  const std::vector<uint8_t> vlr = laszipRecord(chunkSize);
  std::vector<uint8_t> out(head.begin(), head.begin() + ptrdiff_t(header.pointDataOffset));
  out.insert(out.end(), vlr.begin(), vlr.end());
  const auto pointData = uint32_t(out.size());
  store<uint8_t>(out, 104, 0x80);
  store<uint32_t>(out, 96, pointData);
  store<uint32_t>(out, 100, header.vlrCount + 1);
  std::ofstream file(laz, std::ios::binary);
  append<int64_t>(out, 0);  // the chunk table's offset, known at the end
  std::vector<uint32_t> chunkBytes;
  std::vector<uint8_t> records;
  for (uint64_t done = 0; done < header.pointCount;) {
    const auto count = size_t(std::min<uint64_t>(chunkSize, header.pointCount - done));
    records.resize(count * kPoint10Bytes);
    if (!in.readExact(records.data(), records.size())) in.fail("file ends inside its points");
    const size_t start = out.size();
    Point10Encoder encoder(out);
    for (size_t i = 0; i < count; ++i) encoder.add(records.data() + i * kPoint10Bytes);
    encoder.done();
    chunkBytes.push_back(uint32_t(out.size() - start));
    done += count;
    file.write(reinterpret_cast<const char*>(out.data()), std::streamsize(out.size()));
    out.clear();
  }
  const uint64_t table = uint64_t(file.tellp());
  append<uint32_t>(out, 0);
  append<uint32_t>(out, uint32_t(chunkBytes.size()));
  ArithmeticEncoder encoder(out);
  IntegerModels models(32, 2);
  uint32_t previous = 0;
  for (uint32_t bytes : chunkBytes) {
    encoder.encodeInteger(models, int32_t(previous), int32_t(bytes), 1);
    previous = bytes;
  }
  encoder.done();
  file.write(reinterpret_cast<const char*>(out.data()), std::streamsize(out.size()));
  file.seekp(pointData);
  const auto offset = int64_t(table);
  file.write(reinterpret_cast<const char*>(&offset), 8);
  if (!file) throw FileError(laz.string(), std::nullopt, "cannot write");
}

}  // namespace iso::bench
