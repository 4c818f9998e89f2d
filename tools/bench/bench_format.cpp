// iso-bench-format [--chunks N] [--chunk-bytes B] [--dir D]: throughput of the container.
// Writes the same chunks raw and with zstd at three levels, then opens, verifies and decodes each
// file, and prints MB/s, compression ratio and the writer's peak memory (which must not grow with
// the file). Ratios are comparable within one run; the read side runs from the page cache.
#include <fmt/core.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "iso/reader.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "pipeline/base/process.h"

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double peakRssMiB() { return double(iso::peakRssBytes()) / 1048576.0; }

// Bytes that resemble quantized corner data: a smooth signal plus a little noise.
std::vector<std::byte> makeChunk(uint32_t seed, size_t size) {
  std::vector<std::byte> data(size);
  uint32_t state = seed * 2654435761u + 1;
  for (size_t i = 0; i < size; ++i) {
    state = state * 1664525u + 1013904223u;
    const double smooth = 60.0 * std::sin(double(i) * 0.013 + seed) * std::cos(double(i) * 0.0007);
    data[i] = std::byte(static_cast<int8_t>(std::lround(smooth) + int((state >> 28) & 3) - 1));
  }
  return data;
}

struct Config {
  uint32_t chunks = 512;
  size_t chunkBytes = size_t{1} << 20;
  std::filesystem::path dir;
};

void benchCodec(const Config& config, const char* label, iso::Codec codec, int level,
                const std::vector<std::vector<std::byte>>& samples) {
  const std::filesystem::path path = config.dir / fmt::format("bench-{}.iso", label);
  const double raw = double(config.chunks) * double(config.chunkBytes);
  iso::FileHeader header;
  header.maxLevel = 3;
  iso::resetPeakRss();
  auto start = Clock::now();
  {
    iso::Writer writer(path, header, {.zstdLevel = level});
    for (uint32_t i = 0; i < config.chunks; ++i) {
      iso::ChunkDesc desc;
      desc.level = 3;
      desc.key = i % 512;
      desc.codec = codec;
      writer.addChunk(desc, samples[i % samples.size()]);
    }
    writer.finish();
  }
  const double writeSeconds = secondsSince(start);
  const double writeRss = peakRssMiB();
  const double fileBytes = double(std::filesystem::file_size(path));

  start = Clock::now();
  const iso::Reader reader = iso::Reader::open(path);
  const double openSeconds = secondsSince(start);

  start = Clock::now();
  const iso::VerifyResult verified = iso::verifyFile(reader);
  const double verifySeconds = secondsSince(start);
  if (!verified.ok()) throw std::runtime_error("verification failed on the benchmark file");

  start = Clock::now();
  std::vector<std::byte> buffer(config.chunkBytes);
  uint64_t sum = 0;
  for (const iso::ChunkInfo& c : reader.chunks()) {
    if (c.codec == iso::Codec::Raw) {  // zero copy: touch the mapped bytes (checked)
      for (std::byte b : reader.payload(c.id).bytes()) sum += uint64_t(b);
    } else {
      reader.decodePayload(c.id, buffer);
      sum += uint64_t(buffer[0]);
    }
  }
  const double decodeSeconds = secondsSince(start);
  fmt::print("{:<8} {:>9.0f} {:>7.3f} {:>9.0f} {:>9.1f} {:>9.0f} {:>9.0f} {:>9.1f}\n", label,
             raw / writeSeconds / 1e6, raw / fileBytes, fileBytes / 1e6, openSeconds * 1e6,
             fileBytes / verifySeconds / 1e6, raw / decodeSeconds / 1e6, writeRss);
  std::filesystem::remove(path);
  if (sum == 1) fmt::print(" ");  // keep the read loop from being optimized away
}

}  // namespace

int main(int argc, char** argv) {
  Config config;
  const char* out = std::getenv("ISO_BENCH_OUT");
  config.dir = out ? out : std::filesystem::temp_directory_path().string();
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string option = argv[i];
    if (option == "--chunks")
      config.chunks = uint32_t(std::stoul(argv[i + 1]));
    else if (option == "--chunk-bytes")
      config.chunkBytes = std::stoul(argv[i + 1]);
    else if (option == "--dir")
      config.dir = argv[i + 1];
    else {
      fmt::print(stderr, "usage: iso-bench-format [--chunks N] [--chunk-bytes B] [--dir D]\n");
      return 2;
    }
  }
  if ((argc - 1) % 2 != 0) {
    fmt::print(stderr, "usage: iso-bench-format [--chunks N] [--chunk-bytes B] [--dir D]\n");
    return 2;
  }
  try {
    std::filesystem::create_directories(config.dir);
    std::vector<std::vector<std::byte>> samples;
    for (uint32_t i = 0; i < 16; ++i) samples.push_back(makeChunk(i, config.chunkBytes));
    fmt::print("container benchmark: {} chunks x {} bytes = {:.0f} MB of chunk data, in {}\n",
               config.chunks, config.chunkBytes,
               double(config.chunks) * double(config.chunkBytes) / 1e6, config.dir.string());
    fmt::print("{:<8} {:>9} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9}\n", "codec", "write", "ratio",
               "file", "open", "verify", "decode", "write RSS");
    fmt::print("{:<8} {:>9} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9}\n", "", "MB/s", "", "MB", "us",
               "MB/s", "MB/s", "MiB");
    benchCodec(config, "raw", iso::Codec::Raw, 3, samples);
    benchCodec(config, "zstd-1", iso::Codec::Zstd, 1, samples);
    benchCodec(config, "zstd-3", iso::Codec::Zstd, 3, samples);
    benchCodec(config, "zstd-9", iso::Codec::Zstd, 9, samples);
  } catch (const std::exception& error) {
    fmt::print(stderr, "iso-bench-format: {}\n", error.what());
    return 1;
  }
  return 0;
}
