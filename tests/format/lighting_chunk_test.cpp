// Lighting chunks (specs/iso-format.md, "Lighting chunks"): the bytes where the spec puts them, a
// round trip, and a refusal naming the rule for each way a chunk can break the rules.
#include <gtest/gtest.h>

#include <cstring>
#include <functional>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/lighting.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "tests/support/support.h"

namespace iso {
namespace {

const std::filesystem::path kGolden = std::filesystem::path(ISO_TEST_DATA_DIR) / "golden-v2.iso";

uint32_t u32(std::span<const std::byte> b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// The golden file's surface chunk and a lighting of it: corner i gets (i, 2i, 0.5), LOD corner
// i (0.25 i, 0, 1), and the first leaf's corner 3 its own (7, 7, 7).
struct Lit {
  uint32_t surfaceId = 0;
  SurfaceChunk surface;
  ChunkLighting lighting;
};

Lit goldenLighting(const Reader& golden) {
  Lit lit;
  for (const ChunkInfo& c : golden.chunks())
    if (c.kind == kSurfaceKind) lit.surfaceId = c.id;
  lit.surface = decodeSurfaceChunk(golden, lit.surfaceId);
  lit.lighting.surfaceChunk = lit.surfaceId;
  for (size_t i = 0; i < lit.surface.layout.leafCorners.size(); ++i)
    lit.lighting.leaf.push_back({float(i), float(2 * i), 0.5f});
  for (size_t i = 0; i < lit.surface.layout.lodCorners.size(); ++i)
    lit.lighting.lod.push_back({0.25f * float(i), 0.0f, 1.0f});
  for (uint32_t n = 0; n < lit.surface.layout.nodes.size(); ++n)
    if (lit.surface.layout.nodes[n].isLeaf()) {
      lit.lighting.overrides.push_back({n, 3, {7.0f, 7.0f, 7.0f}});
      break;
    }
  return lit;
}

// The golden file's chunks as they are, then `data` as a lighting chunk in the surface chunk's
// cell, with `edit` applied to its description.
void writeLit(const std::filesystem::path& path, const Reader& golden, uint32_t surfaceId,
              const std::vector<std::byte>& data,
              const std::function<void(ChunkDesc&)>& edit = {}) {
  FileHeader header = golden.header();
  Writer writer(path, header);
  for (const ChunkInfo& c : golden.chunks())
    writer.copyChunk(c, golden.bytes().subspan(c.offset, c.storedSize));
  ChunkDesc desc;
  desc.kind = kLightingKind;
  desc.level = golden.chunk(surfaceId).level;
  desc.key = golden.chunk(surfaceId).key;
  desc.codec = Codec::Raw;
  if (edit) edit(desc);
  writer.addChunk(desc, data);
  writer.finish();
}

TEST(LightingChunk, bytesAreWhereTheSpecSaysAndReadBack) {
  test::TempDir dir;
  const Reader golden = Reader::open(kGolden);
  Lit lit = goldenLighting(golden);
  ASSERT_FALSE(lit.lighting.overrides.empty());
  const std::vector<std::byte> data = encodeLightingChunk(lit.lighting);
  const size_t leaf = lit.lighting.leaf.size(), lod = lit.lighting.lod.size();
  ASSERT_EQ(data.size(), 16 + 4 * (leaf + lod) + 8);
  EXPECT_EQ(u32(data, 0), lit.surfaceId);
  EXPECT_EQ(u32(data, 4), leaf);
  EXPECT_EQ(u32(data, 8), lod);
  EXPECT_EQ(u32(data, 12), 1u);
  // RGB9E5: (1, 2, 0.5) is 256·2^-8, 256·2^-7 with the exponent of 2 (bias 15: 2^(e-15-9)):
  // e = 17, mantissas 128, 256, 64.
  EXPECT_EQ(u32(data, 16 + 4), 17u << 27 | 64u << 18 | 256u << 9 | 128u);
  const uint32_t node = lit.lighting.overrides[0].node;
  EXPECT_EQ(u32(data, 16 + 4 * (leaf + lod)), node << 3 | 3u);
  EXPECT_EQ(decodeRgb9e5(u32(data, 16 + 4 * (leaf + lod) + 4)),
            (std::array<float, 3>{7.0f, 7.0f, 7.0f}));

  writeLit(dir / "lit.iso", golden, lit.surfaceId, data);
  const Reader reader = Reader::open(dir / "lit.iso");
  EXPECT_EQ(chunkKindName(reader.chunks().back().kind), "lighting");
  EXPECT_TRUE(verifyFile(reader).ok());
  const std::vector<uint32_t> of = lightingChunks(reader);
  ASSERT_EQ(of[lit.surfaceId], uint32_t(reader.chunks().size() - 1));
  SurfaceChunk chunk = decodeSurfaceChunk(reader, lit.surfaceId);
  attachLighting(reader, of[lit.surfaceId], lit.surfaceId, chunk);
  EXPECT_EQ(chunk.leafValues.irradiance, lit.lighting.leaf);
  EXPECT_EQ(chunk.lodValues.irradiance, lit.lighting.lod);
  EXPECT_EQ(chunk.irradianceOverrides, lit.lighting.overrides);
}

TEST(LightingChunk, everyBrokenRuleIsRefusedByName) {
  test::TempDir dir;
  const Reader golden = Reader::open(kGolden);
  const Lit lit = goldenLighting(golden);
  const auto refused = [&](const std::string& name, ChunkLighting lighting,
                           const std::function<void(ChunkDesc&)>& edit,
                           const std::function<void(std::vector<std::byte>&)>& damage,
                           const std::string& rule) {
    SCOPED_TRACE(name);
    std::vector<std::byte> data = encodeLightingChunk(lighting);
    if (damage) damage(data);
    const std::filesystem::path path = dir / (name + ".iso");
    try {
      writeLit(path, golden, lit.surfaceId, data, edit);
    } catch (const InternalError& error) {
      // A rule of the chunk table: the writer refuses the entry, naming the rule; written as it
      // may be, then the entry changed, the file is refused below.
      EXPECT_NE(std::string(error.what()).find(rule), std::string::npos) << error.what();
      writeLit(path, golden, lit.surfaceId, data);
      test::writeFile(
          path, test::withChangedEntry(
                    test::readFile(path), uint32_t(golden.chunks().size()), [&](ChunkInfo& c) {
                      ChunkDesc d{.kind = c.kind, .level = c.level, .key = c.key};
                      edit(d);
                      c.level = d.level;
                      c.key = d.key;
                      c.parent = d.parent;
                      c.pointCount = d.pointCount;
                    }));
    }
    std::string message;
    try {
      const Reader reader = Reader::open(path);
      const VerifyResult result = verifyFile(reader);
      for (const VerifyProblem& p : result.problems) message += describe(reader, p) + "\n";
      SurfaceChunk chunk = decodeSurfaceChunk(reader, lit.surfaceId);
      attachLighting(reader, uint32_t(reader.chunks().size() - 1), lit.surfaceId, chunk);
      ADD_FAILURE() << "read without an error; verify said: " << message;
    } catch (const FileError& error) {
      message += error.what();
    }
    EXPECT_NE(message.find(rule), std::string::npos) << message;
  };
  refused("points", lit.lighting, [](ChunkDesc& d) { d.pointCount = 5; }, {},
          "a lighting chunk has points");
  refused("parent", lit.lighting, [](ChunkDesc& d) { d.parent = 0; d.level += 1; }, {},
          "a lighting chunk has no parent");
  refused("cell", lit.lighting, [](ChunkDesc& d) { d.key ^= 1; }, {},
          "the lighting chunk's cell is not its surface chunk's");
  ChunkLighting other = lit.lighting;
  other.surfaceChunk = 0;
  refused("not a surface", other, {}, {}, "which is not a surface chunk");
  other = lit.lighting;
  other.leaf.pop_back();
  refused("counts", other, {}, {}, "its surface chunk");
  refused("short", lit.lighting, {}, [](std::vector<std::byte>& d) { d.resize(d.size() - 2); },
          "lighting data is not its header");
  other = lit.lighting;
  other.overrides.push_back(other.overrides[0]);
  refused("unsorted", other, {}, {}, "increasing node and corner order");
  other = lit.lighting;
  for (uint32_t n = 0; n < lit.surface.layout.nodes.size(); ++n)
    if (!lit.surface.layout.nodes[n].isLeaf()) other.overrides = {{n, 0, {1.0f, 1.0f, 1.0f}}};
  ASSERT_FALSE(lit.surface.layout.nodes[other.overrides[0].node].isLeaf());
  refused("not a leaf", other, {}, {}, "which is not a filled leaf");
}

}  // namespace
}  // namespace iso
