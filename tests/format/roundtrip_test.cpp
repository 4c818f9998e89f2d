// Round trips of randomized chunk sets through the writer and the memory-mapped reader.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "iso/check.h"
#include "iso/reader.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "tests/support/support.h"

namespace iso {
namespace {

struct Expected {
  FileHeader header;
  std::vector<ChunkDesc> descs;
  std::vector<std::vector<std::byte>> data;
  std::string metadata;
};

std::vector<AttributeDesc> randomSchema(std::mt19937_64& rng) {
  std::vector<AttributeDesc> schema;
  const Encoding distance[] = {Encoding::Snorm8, Encoding::Snorm16, Encoding::Float32};
  schema.push_back({Semantic::SignedDistance, distance[rng() % 3], 1,
                    std::uniform_real_distribution<float>(0.01f, 4.0f)(rng)});
  if (rng() % 2)
    schema.push_back({Semantic::Normal, rng() % 2 ? Encoding::Oct16 : Encoding::Oct24, 2, 0});
  if (rng() % 2) schema.push_back({Semantic::Color, Encoding::Srgb8, 3, 0});
  if (rng() % 2) schema.push_back({Semantic::Occlusion, Encoding::Unorm8, 1, 0});
  return schema;
}

std::vector<std::byte> randomData(std::mt19937_64& rng, size_t size) {
  std::vector<std::byte> data(size);
  const bool compressible = rng() % 2;
  for (size_t i = 0; i < size; ++i)
    data[i] = compressible ? std::byte((i / 7) % 5) : std::byte(rng());
  return data;
}

// A random but valid chunk tree: each chunk's parent is an earlier, coarser chunk containing it.
Expected makeRandomFile(uint64_t seed, const std::filesystem::path& path) {
  std::mt19937_64 rng(seed);
  Expected e;
  e.header.payloadAlignmentLog2 = uint8_t(3 + rng() % 14);
  e.header.maxLevel = uint8_t(rng() % 22);
  // Origins up to ECEF coordinates, at most 2^31 frame sizes from 0 (kMaxFrameOriginInSizes).
  e.header.frame.origin = {std::ldexp(double(rng() % 1000), int(rng() % 12)),
                           -6.4e6 + double(rng() % 7), double(rng() % 100) * 0.001};
  e.header.frame.size = std::ldexp(1.0 + double(rng() % 1000), int(rng() % 20) - 8);
  e.header.attributes = randomSchema(rng);
  const size_t chunkCount = rng() % 30;
  Writer writer(path, e.header);
  for (size_t i = 0; i < chunkCount; ++i) {
    ChunkDesc d;
    // Blobs and kinds this version does not know (6 to 255): their entries have no rules.
    d.kind = rng() % 4 == 0 ? uint8_t(6 + rng() % 250) : 0;
    d.level = uint8_t(rng() % (e.header.maxLevel + 1));
    d.key = d.level == 0 ? 0 : rng() >> (64 - 3 * d.level);
    for (size_t j = 0; j < i; ++j) {  // the first earlier chunk that contains this one
      const ChunkDesc& p = e.descs[j];
      if (p.level < d.level && cellContains(p.level, p.key, d.level, d.key) && rng() % 2) {
        d.parent = uint32_t(j);
        break;
      }
    }
    d.pointCount = rng() % 1000000;
    d.nodeCount = uint32_t(rng());
    d.leafCount = uint32_t(rng());
    d.geometricError = float(rng() % 1000) / 1024.0f;
    d.codec = rng() % 2 ? Codec::Zstd : Codec::Raw;
    const size_t size = rng() % 8 == 0 ? 0 : rng() % 20000;
    e.descs.push_back(d);
    e.data.push_back(randomData(rng, size));
    EXPECT_EQ(writer.addChunk(d, e.data.back()), i);
  }
  e.metadata = R"({"seed":)" + std::to_string(seed) + R"(,"text":"ä ∂ 𝄞"})";
  writer.setMetadata(e.metadata);
  writer.finish();
  return e;
}

TEST(FormatRoundTrip, randomizedChunkSetsReadBackExactly) {
  test::TempDir dir;
  for (uint64_t seed = 1; seed <= 60; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const auto path = dir / ("random-" + std::to_string(seed) + ".iso");
    const Expected e = makeRandomFile(seed, path);
    const Reader reader = Reader::open(path);
    EXPECT_EQ(reader.header(), e.header);
    EXPECT_EQ(reader.metadata(), e.metadata);
    ASSERT_EQ(reader.chunks().size(), e.descs.size());
    for (uint32_t i = 0; i < e.descs.size(); ++i) {
      const ChunkInfo& c = reader.chunk(i);
      const ChunkDesc& d = e.descs[i];
      EXPECT_EQ(c.id, i);
      EXPECT_EQ(c.kind, d.kind);
      EXPECT_EQ(c.level, d.level);
      EXPECT_EQ(c.key, d.key);
      EXPECT_EQ(c.parent, d.parent);
      EXPECT_EQ(c.pointCount, d.pointCount);
      EXPECT_EQ(c.nodeCount, d.nodeCount);
      EXPECT_EQ(c.leafCount, d.leafCount);
      EXPECT_EQ(c.geometricError, d.geometricError);
      EXPECT_EQ(c.rawSize, e.data[i].size());
      EXPECT_EQ(c.offset % reader.header().payloadAlignment(), 0u);
      if (d.codec == Codec::Raw) {
        EXPECT_EQ(c.codec, Codec::Raw);
      }
      std::vector<std::byte> decoded(c.rawSize);
      reader.decodePayload(i, decoded);
      EXPECT_EQ(decoded, e.data[i]);
    }
    const VerifyResult verified = verifyFile(reader);
    EXPECT_TRUE(verified.ok());
    EXPECT_EQ(verified.chunksChecked, e.descs.size());
  }
}

TEST(FormatRoundTrip, compressibleChunksAreStoredWithZstdAndRandomOnesRaw) {
  test::TempDir dir;
  std::vector<std::byte> smooth(100000), noise(100000);
  std::mt19937 rng(7);
  for (size_t i = 0; i < smooth.size(); ++i) {
    smooth[i] = std::byte(i % 3);
    noise[i] = std::byte(rng());
  }
  FileHeader header;
  Writer writer(dir / "codecs.iso", header);
  writer.addChunk({.codec = Codec::Zstd}, smooth);
  writer.addChunk({.codec = Codec::Zstd}, noise);
  writer.addChunk({.codec = Codec::Raw}, smooth);
  writer.finish();
  const Reader reader = Reader::open(dir / "codecs.iso");
  EXPECT_EQ(reader.chunk(0).codec, Codec::Zstd);
  EXPECT_LT(reader.chunk(0).storedSize, smooth.size() / 100);
  EXPECT_EQ(reader.chunk(1).codec, Codec::Raw);
  EXPECT_EQ(reader.chunk(1).storedSize, noise.size());
  EXPECT_EQ(reader.chunk(2).codec, Codec::Raw);
}

TEST(FormatRoundTrip, rawPayloadsAreZeroCopyAndPageAligned) {
  test::TempDir dir;
  std::vector<std::byte> data(10000, std::byte{42});
  data[17] = std::byte{1};
  {
    Writer writer(dir / "raw.iso", FileHeader{});
    writer.addChunk({.codec = Codec::Raw}, data);
    writer.addChunk({.codec = Codec::Raw}, data);
    writer.finish();
  }
  const Reader reader = Reader::open(dir / "raw.iso");
  const std::span<const std::byte> file = reader.bytes();
  for (uint32_t i = 0; i < 2; ++i) {
    const ChunkData stored = reader.payload(i);
    const std::span<const std::byte> payload = stored.bytes();
    EXPECT_EQ(payload.data(), file.data() + reader.chunk(i).offset);  // points into the mapping
    EXPECT_EQ(reinterpret_cast<uintptr_t>(payload.data()) % 4096, 0u);
    EXPECT_EQ(std::memcmp(payload.data(), data.data(), data.size()), 0);
  }
}

TEST(FormatRoundTrip, emptyFileHasNoChunksAndOpens) {
  test::TempDir dir;
  {
    Writer writer(dir / "empty.iso", FileHeader{});
    writer.finish();
  }
  const Reader reader = Reader::open(dir / "empty.iso");
  EXPECT_TRUE(reader.chunks().empty());
  EXPECT_EQ(reader.metadata(), "{}");
  EXPECT_EQ(reader.fileSize(), 4096u + 2u + 64u);
  EXPECT_TRUE(verifyFile(reader).ok());
}

TEST(FormatRoundTrip, decodeRejectsSmallBuffersAndBadIds) {
  test::TempDir dir;
  std::vector<std::byte> data(1000, std::byte{3});
  {
    Writer writer(dir / "f.iso", FileHeader{});
    writer.addChunk({}, data);
    writer.finish();
  }
  const Reader reader = Reader::open(dir / "f.iso");
  std::vector<std::byte> small(999);
  EXPECT_THROW(reader.decodePayload(0, small), InternalError);
  EXPECT_THROW(reader.chunk(1), std::out_of_range);
  EXPECT_THROW(reader.payload(1), std::out_of_range);
  EXPECT_THROW(reader.checkPayload(1), std::out_of_range);
}

}  // namespace
}  // namespace iso
