// tests/data/golden-v2.iso pins the bytes of the current format (2.2): the current writer must
// reproduce it exactly, the reader must read the expected values from it, and the byte offsets
// asserted here are the ones of specs/iso-format.md, written independently of format/src/layout.h.
#include <gtest/gtest.h>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cmath>
#include <cstring>

#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/verify.h"
#include "tests/support/support.h"

namespace iso {
namespace {

const std::filesystem::path kGolden = std::filesystem::path(ISO_TEST_DATA_DIR) / "golden-v2.iso";

template <typename T>
T at(const std::vector<std::byte>& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

uint64_t xxh3(const std::vector<std::byte>& bytes, size_t offset, size_t size) {
  return XXH3_64bits(bytes.data() + offset, size);
}

TEST(FormatGolden, writerReproducesTheGoldenFileByteForByte) {
  test::TempDir dir;
  test::writeGoldenFile(dir / "golden.iso");
  const std::vector<std::byte> written = test::readFile(dir / "golden.iso");
  const std::vector<std::byte> golden = test::readFile(kGolden);
  ASSERT_EQ(written.size(), golden.size());
  for (size_t i = 0; i < golden.size(); ++i)
    ASSERT_EQ(written[i], golden[i]) << "first difference at byte " << i
                                     << " (regenerate with make_golden only for a format change)";
}

TEST(FormatGolden, headerBytesAreWhereTheSpecSays) {
  const std::vector<std::byte> b = test::readFile(kGolden);
  const uint8_t magic[8] = {0x89, 0x49, 0x53, 0x4F, 0x0D, 0x0A, 0x1A, 0x0A};
  EXPECT_EQ(std::memcmp(b.data(), magic, 8), 0);
  EXPECT_EQ(at<uint16_t>(b, 8), 2);      // versionMajor
  EXPECT_EQ(at<uint16_t>(b, 10), 2);     // versionMinor
  EXPECT_EQ(at<uint32_t>(b, 12), 256u);  // headerSize
  EXPECT_EQ(at<uint32_t>(b, 16), 0u);    // flags
  EXPECT_EQ(at<uint8_t>(b, 20), 12);     // payloadAlignmentLog2
  EXPECT_EQ(at<uint8_t>(b, 21), 3);      // maxLevel
  EXPECT_EQ(at<uint8_t>(b, 22), 3);      // attributeCount
  EXPECT_EQ(at<double>(b, 24), 515000.25);
  EXPECT_EQ(at<double>(b, 32), 4918000.5);
  EXPECT_EQ(at<double>(b, 40), -1234.125);
  EXPECT_EQ(at<double>(b, 48), 64.0);
  // attributes[0..2]: semantic, encoding, components, reserved, scale
  EXPECT_EQ(at<uint32_t>(b, 56), 0x00010101u);  // signed_distance, snorm8, 1
  EXPECT_EQ(at<float>(b, 60), 0.5f);
  EXPECT_EQ(at<uint32_t>(b, 64), 0x00020302u);  // normal, oct16, 2
  EXPECT_EQ(at<uint32_t>(b, 72), 0x00030503u);  // color, srgb8, 3
  for (size_t i = 80; i < 248; ++i) EXPECT_EQ(b[i], std::byte{0}) << "byte " << i;
  EXPECT_EQ(at<uint64_t>(b, 248), xxh3(b, 0, 248));
  for (size_t i = 256; i < 4096; ++i) ASSERT_EQ(b[i], std::byte{0}) << "padding byte " << i;
}

TEST(FormatGolden, trailerAndChunkTableBytesAreWhereTheSpecSays) {
  const std::vector<std::byte> b = test::readFile(kGolden);
  const size_t t = b.size() - 64;
  const uint8_t magic[8] = {0x89, 0x49, 0x53, 0x4F, 0x45, 0x4E, 0x44, 0x0A};
  EXPECT_EQ(std::memcmp(b.data() + t + 56, magic, 8), 0);
  const uint64_t table = at<uint64_t>(b, t + 0);
  const uint32_t count = at<uint32_t>(b, t + 8);
  EXPECT_EQ(count, 6u);
  EXPECT_EQ(at<uint32_t>(b, t + 12), 80u);
  EXPECT_EQ(at<uint64_t>(b, t + 16), table + 80 * count);
  const uint64_t metadataOffset = at<uint64_t>(b, t + 16);
  const uint64_t metadataSize = at<uint64_t>(b, t + 24);
  EXPECT_EQ(metadataOffset + metadataSize, t);
  EXPECT_EQ(at<uint64_t>(b, t + 32), xxh3(b, table, 80 * count));
  EXPECT_EQ(at<uint64_t>(b, t + 40), xxh3(b, metadataOffset, metadataSize));
  EXPECT_EQ(at<uint64_t>(b, t + 48), xxh3(b, t, 48));
  const std::string metadata(reinterpret_cast<const char*>(b.data() + metadataOffset),
                             metadataSize);
  EXPECT_EQ(metadata, test::goldenMetadata());

  // Payloads at 4096-aligned offsets in table order: 0 (zstd), 1 (raw 300 B), 2 (zstd),
  // 3 (empty, raw), 4 (raw 64 B, kind 7), 5 (raw surface).
  uint64_t expectedOffset = 4096;
  for (uint32_t i = 0; i < count; ++i) {
    const size_t e = table + 80 * i;
    EXPECT_EQ(at<uint64_t>(b, e + 0), expectedOffset) << "chunk " << i;
    const uint64_t stored = at<uint64_t>(b, e + 8);
    EXPECT_EQ(at<uint64_t>(b, e + 24), xxh3(b, expectedOffset, stored)) << "chunk " << i;
    EXPECT_EQ(at<uint32_t>(b, e + 48), i);   // id
    EXPECT_EQ(at<uint8_t>(b, e + 71), 0);    // reserved
    EXPECT_EQ(at<uint64_t>(b, e + 72), 0u);  // reserved
    expectedOffset = (expectedOffset + stored + 4095) / 4096 * 4096;
  }
  EXPECT_EQ(expectedOffset, table);
  const size_t e0 = table, e1 = table + 80, e2 = table + 160, e3 = table + 240, e4 = table + 320;
  EXPECT_EQ(at<uint8_t>(b, e0 + 69), 1);             // codec zstd
  EXPECT_EQ(at<uint64_t>(b, e0 + 16), 2000u);        // rawSize
  EXPECT_EQ(at<uint32_t>(b, e0 + 52), 0xFFFFFFFFu);  // no parent
  EXPECT_EQ(at<uint64_t>(b, e0 + 40), 1000u);        // pointCount
  EXPECT_EQ(at<uint32_t>(b, e0 + 56), 9u);           // nodeCount
  EXPECT_EQ(at<uint32_t>(b, e0 + 60), 8u);           // leafCount
  EXPECT_EQ(at<float>(b, e0 + 64), 0.25f);           // geometricError
  EXPECT_EQ(at<uint8_t>(b, e1 + 69), 0);             // incompressible: raw
  EXPECT_EQ(at<uint64_t>(b, e1 + 8), 300u);
  EXPECT_EQ(at<uint64_t>(b, e1 + 32), 5u);  // key
  EXPECT_EQ(at<uint8_t>(b, e1 + 68), 1);    // level
  EXPECT_EQ(at<uint32_t>(b, e2 + 52), 1u);  // parent
  EXPECT_EQ(at<uint64_t>(b, e2 + 32), 42u);
  EXPECT_EQ(at<uint64_t>(b, e3 + 8), 0u);  // empty
  EXPECT_EQ(at<uint8_t>(b, e4 + 70), 7);   // kind
  EXPECT_EQ(at<uint64_t>(b, e4 + 32), 0x3Fu);
  EXPECT_EQ(at<uint8_t>(b, e4 + 68), 3);
  const size_t e5 = table + 400;
  EXPECT_EQ(at<uint8_t>(b, e5 + 70), 1);    // kind surface
  EXPECT_EQ(at<uint32_t>(b, e5 + 56), 3u);  // nodeCount
  // The surface data (specs/iso-format.md, "Surface chunks"): header, root key, masks, arrays.
  const size_t s = at<uint64_t>(b, e5);
  EXPECT_EQ(at<uint32_t>(b, s + 0), 1u);     // rootCount
  EXPECT_EQ(at<uint32_t>(b, s + 4), 3u);     // nodeCount
  EXPECT_EQ(at<uint32_t>(b, s + 8), 12u);    // leaf corners: two leaves sharing a face
  EXPECT_EQ(at<uint32_t>(b, s + 12), 8u);    // LOD corners of the internal node
  EXPECT_EQ(at<uint8_t>(b, s + 16), 1);      // startLevel
  EXPECT_EQ(at<uint8_t>(b, s + 17), 2);      // depth
  EXPECT_EQ(at<uint64_t>(b, s + 24), 6u);    // root key
  EXPECT_EQ(at<uint8_t>(b, s + 32), 0b101);  // root's children: octants 0 and 2
  EXPECT_EQ(at<uint16_t>(b, s + 33), 0);     // two leaves
  // snorm8 distances from byte 36: 12 leaf corners (scale level 2), pad, 8 LOD corners (level 1).
  const double leafUnit = std::sqrt(3.0) / 4.0 * 0.5, lodUnit = std::sqrt(3.0) / 2.0 * 0.5;
  const test::GoldenSurface g = test::goldenSurface();
  for (int i = 0; i < 12; ++i)
    EXPECT_EQ(at<int8_t>(b, s + 36 + size_t(i)),
              std::lround(g.leafValues.distance[size_t(i)] / leafUnit * 127.0));
  for (int i = 0; i < 8; ++i)
    EXPECT_EQ(at<int8_t>(b, s + 48 + size_t(i)),
              std::lround(g.lodValues.distance[size_t(i)] / lodUnit * 127.0));
  EXPECT_EQ(at<uint64_t>(b, e5 + 8), 36u + 12 + 8 + 24 + 16 + 36 + 24);  // + normals and colors
}

TEST(FormatGolden, surfaceChunkDecodesToItsValues) {
  const Reader reader = Reader::open(kGolden);
  const SurfaceChunk chunk = decodeSurfaceChunk(reader, 5);
  const test::GoldenSurface g = test::goldenSurface();
  ASSERT_EQ(chunk.layout.nodes.size(), 3u);
  EXPECT_EQ(chunk.layout.nodes[0].firstChild, 1u);
  EXPECT_EQ(chunk.layout.nodes[1].key, 6u << 3);
  EXPECT_EQ(chunk.layout.nodes[2].key, (6u << 3) | 2);
  // The second leaf (octant 2, one cell up in y) shares its lower face with the first.
  for (int c : {0, 1, 4, 5})
    EXPECT_EQ(chunk.layout.nodes[2].corners[size_t(c)],
              chunk.layout.nodes[1].corners[size_t(c + 2)]);
  ASSERT_EQ(chunk.leafValues.size(), 12u);
  ASSERT_EQ(chunk.lodValues.size(), 8u);
  const double leafStep = std::sqrt(3.0) / 4.0 * 0.5 / 127.0,
               lodStep = std::sqrt(3.0) / 2.0 * 0.5 / 127.0;
  for (size_t i = 0; i < 12; ++i) {
    EXPECT_NEAR(chunk.leafValues.distance[i], g.leafValues.distance[i], 0.5 * leafStep + 1e-7);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(chunk.leafValues.normal[i][size_t(k)], g.leafValues.normal[i][size_t(k)], 0.02);
      EXPECT_NEAR(chunk.leafValues.color[i][size_t(k)], g.leafValues.color[i][size_t(k)], 0.01);
    }
  }
  for (size_t i = 0; i < 8; ++i)
    EXPECT_NEAR(chunk.lodValues.distance[i], g.lodValues.distance[i], 0.5 * lodStep + 1e-7);
}

TEST(FormatGolden, readerReadsTheExpectedValues) {
  const Reader reader = Reader::open(kGolden);
  EXPECT_EQ(reader.header(), test::goldenHeader());
  EXPECT_EQ(reader.metadata(), test::goldenMetadata());
  const std::vector<test::GoldenChunk> expected = test::goldenChunks();
  ASSERT_EQ(reader.chunks().size(), expected.size());
  for (uint32_t i = 0; i < expected.size(); ++i) {
    const ChunkInfo& c = reader.chunk(i);
    const ChunkDesc& d = expected[i].desc;
    EXPECT_EQ(c.kind, d.kind);
    EXPECT_EQ(c.level, d.level);
    EXPECT_EQ(c.key, d.key);
    EXPECT_EQ(c.parent, d.parent);
    EXPECT_EQ(c.pointCount, d.pointCount);
    EXPECT_EQ(c.geometricError, d.geometricError);
    std::vector<std::byte> data(c.rawSize);
    reader.decodePayload(i, data);
    EXPECT_EQ(data, expected[i].data) << "chunk " << i;
  }
  EXPECT_EQ(chunkKindName(reader.chunk(4).kind), "unknown");
  EXPECT_EQ(chunkKindName(reader.chunk(5).kind), "surface");
  EXPECT_TRUE(verifyFile(reader).ok());
}

// Files of versions 1.2, 2.0 and 2.1 (tests/data/golden-v1.iso, golden-v2.0.iso and
// golden-v2.1.iso, the golden file before 2.0, 2.1 and 2.2): every 1.x file is a valid 2.0 file,
// every 2.x file a valid file of a later 2.x, and this reader reads each as the same content.
void expectReadAsTheCurrentGolden(const std::string& name, uint16_t major, uint16_t minor) {
  SCOPED_TRACE(name);
  const Reader old = Reader::open(std::filesystem::path(ISO_TEST_DATA_DIR) / name);
  const Reader current = Reader::open(kGolden);
  EXPECT_EQ(old.header().versionMajor, major);
  EXPECT_EQ(old.header().versionMinor, minor);
  FileHeader header = old.header();
  header.versionMajor = kFormatMajor;
  header.versionMinor = kFormatMinor;
  EXPECT_EQ(header, current.header());
  ASSERT_EQ(old.chunks().size(), current.chunks().size());
  for (uint32_t i = 0; i < old.chunks().size(); ++i) {
    std::vector<std::byte> a(old.chunk(i).rawSize), b(current.chunk(i).rawSize);
    old.decodePayload(i, a);
    current.decodePayload(i, b);
    EXPECT_EQ(a, b) << "chunk " << i;
  }
  EXPECT_TRUE(verifyFile(old).ok());
}

TEST(FormatGolden, aVersion1FileIsReadAsTheSameContent) {
  expectReadAsTheCurrentGolden("golden-v1.iso", 1, 2);
}

TEST(FormatGolden, aVersion2Point0FileIsReadAsTheSameContent) {
  expectReadAsTheCurrentGolden("golden-v2.0.iso", 2, 0);
}

TEST(FormatGolden, aVersion2Point1FileIsReadAsTheSameContent) {
  expectReadAsTheCurrentGolden("golden-v2.1.iso", 2, 1);
}

TEST(FormatGolden, checksumIsXxh3WithSeedZero) {
  // The reference value of XXH3_64bits on empty input (xxHash 0.8 specification).
  EXPECT_EQ(XXH3_64bits(nullptr, 0), 0x2D06800538D394C2ull);
}

}  // namespace
}  // namespace iso
