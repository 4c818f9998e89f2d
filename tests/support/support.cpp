#include "tests/support/support.h"

#include "iso/points.h"
#include "iso/lighting.h"
#include "iso/reader.h"

#define XXH_INLINE_ALL
#include <unistd.h>
#include <xxhash.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <stdexcept>

namespace iso::test {
namespace {

uint64_t load64(const std::vector<std::byte>& b, size_t at) {
  uint64_t v;
  std::memcpy(&v, b.data() + at, 8);
  return v;
}

void store64(std::vector<std::byte>& b, size_t at, uint64_t v) {
  std::memcpy(b.data() + at, &v, 8);
}

uint64_t hash(const std::vector<std::byte>& b, size_t at, size_t size) {
  return XXH3_64bits(b.data() + at, size);
}

}  // namespace

TempDir::TempDir() {
  static std::atomic<int> counter{0};
  path_ = std::filesystem::temp_directory_path() /
          ("iso-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ignored;
  std::filesystem::remove_all(path_, ignored);
}

ReadOnlyDirectory::ReadOnlyDirectory(const std::filesystem::path& path) : path_(path) {
  std::filesystem::create_directories(path_);
  if (::geteuid() != 0) {
    ok_ = true;  // permissions hold for other users
    return;
  }
  const std::string mount = "mount -t tmpfs -o size=4m tmpfs '" + path_.string() + "' 2>/dev/null";
  mounted_ = ok_ = std::system(mount.c_str()) == 0;
}

void ReadOnlyDirectory::lock() {
  if (mounted_) {
    const std::string remount = "mount -o remount,ro '" + path_.string() + "' 2>/dev/null";
    ok_ = std::system(remount.c_str()) == 0;
  } else {
    std::filesystem::permissions(path_, std::filesystem::perms(0555));
  }
}

ReadOnlyDirectory::~ReadOnlyDirectory() {
  if (mounted_) {
    const std::string unmount = "umount '" + path_.string() + "' 2>/dev/null";
    (void)std::system(unmount.c_str());
  } else {
    std::error_code ignored;
    std::filesystem::permissions(path_, std::filesystem::perms(0755), ignored);
  }
}

std::filesystem::path builtPath(const char* variable, const char* built) {
  const char* set = std::getenv(variable);
  return set != nullptr && *set != '\0' ? std::filesystem::path(set) : std::filesystem::path(built);
}

std::vector<std::byte> readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  std::vector<char> chars((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::byte> bytes(chars.size());
  if (!chars.empty()) std::memcpy(bytes.data(), chars.data(), chars.size());
  return bytes;
}

void writeFile(const std::filesystem::path& path, const std::vector<std::byte>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

// Offsets are those of specs/iso-format.md, written here independently of format/src/layout.h.
void resealChecksums(std::vector<std::byte>& b) {
  if (b.size() < 256 + 64) return;
  store64(b, 248, hash(b, 0, 248));
  const size_t trailer = b.size() - 64;
  const uint64_t tableOffset = load64(b, trailer + 0);
  uint32_t count;
  std::memcpy(&count, b.data() + trailer + 8, 4);
  const uint64_t tableBytes = uint64_t{count} * 80;
  if (tableOffset <= trailer && tableBytes <= trailer - tableOffset)
    store64(b, trailer + 32, hash(b, size_t(tableOffset), size_t(tableBytes)));
  const uint64_t metadataOffset = load64(b, trailer + 16);
  const uint64_t metadataSize = load64(b, trailer + 24);
  if (metadataOffset <= trailer && metadataSize <= trailer - metadataOffset)
    store64(b, trailer + 40, hash(b, size_t(metadataOffset), size_t(metadataSize)));
  store64(b, trailer + 48, hash(b, trailer, 48));
}

std::vector<std::byte> withChangedEntry(std::vector<std::byte> bytes, uint32_t chunk,
                                        const std::function<void(ChunkInfo&)>& change) {
  ChunkInfo c = Reader::fromMemory(bytes, "changed").chunk(chunk);
  change(c);
  const size_t at = size_t(load64(bytes, bytes.size() - 64)) + size_t{80} * chunk;
  const auto put = [&](size_t offset, const auto& value) {
    std::memcpy(bytes.data() + at + offset, &value, sizeof value);
  };
  put(0, c.offset);
  put(8, c.storedSize);
  put(16, c.rawSize);
  put(24, c.checksum);
  put(32, c.key);
  put(40, c.pointCount);
  put(48, c.id);
  put(52, c.parent);
  put(56, c.nodeCount);
  put(60, c.leafCount);
  put(64, c.geometricError);
  put(68, c.level);
  put(69, c.codec);
  put(70, c.kind);
  resealChecksums(bytes);
  return bytes;
}

FileHeader goldenHeader() {
  FileHeader h;
  h.maxLevel = 3;
  h.frame.origin = {515000.25, 4918000.5, -1234.125};
  h.frame.size = 64.0;
  h.attributes = {{Semantic::SignedDistance, Encoding::Snorm8, 1, 0.5f},
                  {Semantic::Normal, Encoding::Oct16, 2, 0.0f},
                  {Semantic::Color, Encoding::Srgb8, 3, 0.0f}};
  return h;
}

std::vector<GoldenChunk> goldenChunks() {
  std::vector<GoldenChunk> chunks(5);
  // 0: the root, compressible, zstd.
  chunks[0].desc = {.level = 0,
                    .key = 0,
                    .pointCount = 1000,
                    .nodeCount = 9,
                    .leafCount = 8,
                    .geometricError = 0.25f,
                    .codec = Codec::Zstd};
  for (int i = 0; i < 2000; ++i) chunks[0].data.push_back(std::byte((i * 7) % 13));
  // 1: incompressible bytes, asked for zstd, so stored raw.
  chunks[1].desc = {.level = 1,
                    .key = 5,
                    .parent = 0,
                    .pointCount = 600,
                    .nodeCount = 1,
                    .leafCount = 1,
                    .geometricError = 0.125f,
                    .codec = Codec::Zstd};
  uint32_t state = 12345;
  for (int i = 0; i < 300; ++i) {
    state = state * 1664525u + 1013904223u;
    chunks[1].data.push_back(std::byte(state >> 24));
  }
  // 2: a grandchild of the root inside chunk 1's cell, text, zstd.
  chunks[2].desc = {.level = 2,
                    .key = (5 << 3) | 2,
                    .parent = 1,
                    .pointCount = 250,
                    .nodeCount = 3,
                    .leafCount = 2,
                    .geometricError = 0.0f,
                    .codec = Codec::Zstd};
  const std::string text = "the surface is the zero set of the trilinear interpolation. ";
  for (int i = 0; i < 25; ++i)
    for (char c : text) chunks[2].data.push_back(std::byte(c));
  // 3: an empty chunk, raw.
  chunks[3].desc = {.level = 1, .key = 0, .parent = 0, .codec = Codec::Raw};
  // 4: a chunk of a kind this version does not know (readers skip it), raw.
  chunks[4].desc = {
      .kind = 7, .level = 3, .key = 0x3F, .parent = 3, .pointCount = 1, .codec = Codec::Raw};
  for (int i = 0; i < 64; ++i) chunks[4].data.push_back(std::byte(255 - i));
  // 5: a surface chunk: one internal node (level 1, key 6) with two filled leaves.
  chunks.push_back({});
  chunks[5].desc = {.kind = kSurfaceKind,
                    .level = 1,
                    .key = 6,
                    .parent = 0,
                    .pointCount = 40,
                    .nodeCount = 3,
                    .leafCount = 2,
                    .geometricError = 0.01f,
                    .codec = Codec::Raw};
  const GoldenSurface surface = goldenSurface();
  const CornerLayout layout = layoutSurface(surface.topology, 1, 6, goldenHeader().maxLevel);
  chunks[5].data = encodeSurfaceChunk(surface.topology, layout, goldenHeader().attributes,
                                      surface.leafValues, surface.lodValues);
  return chunks;
}

GoldenSurface goldenSurface() {
  GoldenSurface g;
  g.topology.startLevel = 1;
  g.topology.depth = 2;
  g.topology.rootKeys = {6};
  g.topology.childMasks = {0b00000101, 0, 0};
  const auto fill = [](CornerValues& v, size_t n, float base) {
    for (size_t i = 0; i < n; ++i) {
      const float t = float(i) / float(n);
      v.distance.push_back((t - 0.5f) * base);
      const float x = 0.6f - t, y = 0.3f, z = std::sqrt(1.0f - x * x - y * y);
      v.normal.push_back({x, y, z});
      v.color.push_back({t, 0.5f, 1.0f - t});
    }
  };
  fill(g.leafValues, 12, 0.2f);
  fill(g.lodValues, 8, 0.4f);
  return g;
}

std::string goldenMetadata() {
  return R"({"generator":"iso golden file v1","note":"pins the bytes of format 1.0"})";
}

void writeGoldenFile(const std::filesystem::path& path) {
  Writer writer(path, goldenHeader(), {.zstdLevel = 3});
  for (const GoldenChunk& c : goldenChunks()) writer.addChunk(c.desc, c.data);
  writer.setMetadata(goldenMetadata());
  writer.finish();
}

void writeLightingSeedFile(const std::filesystem::path& golden, const std::filesystem::path& path) {
  const Reader in = Reader::open(golden);
  Writer writer(path, in.header());
  for (const ChunkInfo& c : in.chunks()) writer.copyChunk(c, in.bytes().subspan(c.offset, c.storedSize));
  for (const ChunkInfo& c : in.chunks()) {
    if (c.kind != kSurfaceKind) continue;
    const SurfaceChunk surface = decodeSurfaceChunk(in, c.id);
    ChunkLighting lighting;
    lighting.surfaceChunk = c.id;
    for (size_t i = 0; i < surface.layout.leafCorners.size(); ++i)
      lighting.leaf.push_back({float(i), 0.5f, 2.0f});
    lighting.lod.assign(surface.layout.lodCorners.size(), {1.0f, 1.0f, 1.0f});
    for (uint32_t n = 0; n < surface.layout.nodes.size(); ++n)
      if (surface.layout.nodes[n].isLeaf()) lighting.overrides.push_back({n, 5, {3.0f, 0.0f, 1.0f}});
    ChunkDesc desc;
    desc.kind = kLightingKind;
    desc.level = c.level;
    desc.key = c.key;
    desc.codec = Codec::Raw;
    writer.addChunk(desc, encodeLightingChunk(lighting));
  }
  writer.finish();
}

void writePointsSeedFile(const std::filesystem::path& path) {
  FileHeader header;
  header.payloadAlignmentLog2 = 3;
  header.maxLevel = 4;
  Writer writer(path, header);
  for (int variant = 0; variant < 2; ++variant) {
    PointsChunk points;
    points.stepBits = 20;
    for (int i = 0; i < 60; ++i) {
      points.offsets.push_back({i * 97 % 4096, i * 13 % 4096, i * 7 % 4096});
      if (variant == 1) {
        points.colors.push_back({uint16_t(i * 1000), uint16_t(65535 - i), 257});
        points.normals.push_back({int16_t(i * 500), int16_t(-i * 300), 32767});
        points.radii.push_back(uint16_t(9000 + i * 17));
      }
    }
    ChunkDesc desc;
    desc.kind = kPointsKind;
    desc.level = 2;
    desc.key = uint64_t(variant) * 9;
    desc.geometricError = variant == 1 ? 0.002f : 0.0f;
    desc.pointCount = points.size();
    desc.codec = variant == 0 ? Codec::Raw : Codec::Zstd;
    const std::vector<std::byte> data = encodePointsChunk(points);
    const uint32_t id = writer.addChunk(desc, data);
    // Since 2.1: values of the points (one without a value), and the same points as volume points.
    std::vector<double> values;
    for (int i = 0; i < 60; ++i) values.push_back(i == 7 ? std::nan("") : 0.25 * i - 3.0);
    const std::vector<uint32_t> order = decodedPointOrder(data, points);
    std::vector<double> decoded(order.size());
    for (size_t i = 0; i < order.size(); ++i) decoded[i] = values[order[i]];
    ChunkDesc valuesDesc = desc;
    valuesDesc.kind = kValuesKind;
    valuesDesc.geometricError = 0.0f;
    valuesDesc.codec = Codec::Zstd;
    writer.addChunk(valuesDesc,
                    encodeValuesChunk(quantizeValues(variant == 0 ? "intensity" : "value", id,
                                                     decoded)));
    if (variant == 1) {
      desc.kind = kVolumePointsKind;
      writer.addChunk(desc, data);
    }
  }
  writer.finish();
}

}  // namespace iso::test
