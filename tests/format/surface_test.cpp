// Surface chunks (specs/iso-format.md, "Surface chunks"): corner numbering, quantization round
// trips, and rejection of every topology or payload that breaks the rules.
#include <gtest/gtest.h>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <bit>
#include <map>
#include <random>
#include <tuple>

#include <cmath>
#include <cstring>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/quantize.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "tests/support/support.h"

namespace iso {
namespace {

SurfaceTopology twoLeaves() {
  SurfaceTopology t;
  t.startLevel = 1;
  t.depth = 2;
  t.rootKeys = {6};
  t.childMasks = {0b00000101, 0, 0};
  return t;
}

TEST(SurfaceLayout, sharedCornersAreNumberedOnce) {
  const CornerLayout layout = layoutSurface(twoLeaves(), 1, 6, 3);
  ASSERT_EQ(layout.nodes.size(), 3u);
  EXPECT_EQ(layout.leafCorners.size(), 12u);  // two cubes sharing a face
  EXPECT_EQ(layout.lodCorners.size(), 8u);
  EXPECT_EQ(layout.nodes[0].firstChild, 1u);
  for (int c : {0, 1, 4, 5})
    EXPECT_EQ(layout.nodes[2].corners[size_t(c)], layout.nodes[1].corners[size_t(c + 2)]);
  for (const CornerKey& k : layout.leafCorners) EXPECT_EQ(k.level, 2);
}

// Random topologies of many levels, from nodes whose corners are mostly shared to leaves that
// share none (so that the numbering's table grows), against a numbering by a std::map: corners in
// the order nodes first use them, a leaf corner at the coarsest leaf using it, LOD corners one per
// point and level.
TEST(SurfaceLayout, cornersAreNumberedInFirstUseOrderAsAMapNumbersThem) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 40; ++trial) {
    SurfaceTopology t;
    t.startLevel = 2;
    t.depth = 6;
    t.rootKeys = {9, 10, 13};
    const double childOdds = trial % 2 ? 0.9 : 0.25;  // dense: shared corners; sparse: few
    std::bernoulli_distribution child(childOdds);
    size_t levelBegin = 0, levelEnd = t.rootKeys.size();
    for (int d = 0; d < t.depth; ++d) {
      size_t next = levelEnd;
      for (size_t i = levelBegin; i < levelEnd; ++i) {
        uint8_t mask = 0;
        if (d + 1 < t.depth)
          for (int o = 0; o < 8; ++o) mask |= uint8_t(child(rng) ? 1 << o : 0);
        t.childMasks.push_back(mask);
        next += size_t(std::popcount(mask));
      }
      levelBegin = levelEnd;
      levelEnd = next;
    }
    const CornerLayout layout = layoutSurface(t, 1, 1, 7);
    std::map<std::tuple<uint32_t, uint32_t, uint32_t, int>, uint32_t> leafNumber, lodNumber;
    std::vector<uint8_t> leafLevel;
    for (const SurfaceNode& node : layout.nodes)
      for (int c = 0; c < kCorners; ++c) {
        const GridPoint p = cornerPoint(node.level, node.key, c);
        auto& numbers = node.isLeaf() ? leafNumber : lodNumber;
        const auto key = std::make_tuple(p.x, p.y, p.z, node.isLeaf() ? -1 : int(node.level));
        const auto [at, added] = numbers.try_emplace(key, uint32_t(numbers.size()));
        ASSERT_EQ(node.corners[size_t(c)], at->second) << trial;
        const std::vector<CornerKey>& keys = node.isLeaf() ? layout.leafCorners : layout.lodCorners;
        ASSERT_EQ(keys[at->second].point, p) << trial;
        if (node.isLeaf()) {
          if (added) leafLevel.push_back(node.level);
          leafLevel[at->second] = std::min(leafLevel[at->second], node.level);
        } else {
          EXPECT_EQ(keys[at->second].level, node.level);
        }
      }
    ASSERT_EQ(layout.leafCorners.size(), leafNumber.size());
    ASSERT_EQ(layout.lodCorners.size(), lodNumber.size());
    for (size_t i = 0; i < leafLevel.size(); ++i)
      EXPECT_EQ(layout.leafCorners[i].level, leafLevel[i]) << trial;
  }
}

TEST(SurfaceLayout, rejectsTopologiesThatBreakTheRules) {
  auto rejects = [](SurfaceTopology t, uint8_t chunkLevel, uint64_t chunkKey, const char* why) {
    std::string problem;
    EXPECT_FALSE(tryLayoutSurface(t, chunkLevel, chunkKey, 5, problem)) << "accepted: " << why;
    EXPECT_NE(problem.find(why), std::string::npos) << problem;
    // Made by a caller rather than read from a file, the same topology is a bug.
    EXPECT_THROW(layoutSurface(t, chunkLevel, chunkKey, 5), InternalError) << why;
  };
  SurfaceTopology t = twoLeaves();
  t.depth = 0;
  rejects(t, 1, 6, "depth is 0");
  rejects(twoLeaves(), 2, 6, "above the chunk's cell");
  t = twoLeaves();
  t.depth = 6;
  rejects(t, 1, 6, "maximum level");
  t = twoLeaves();
  t.rootKeys = {};
  rejects(t, 1, 6, "no roots");
  t = twoLeaves();
  t.rootKeys = {5};
  rejects(t, 1, 6, "not inside the chunk's cell");
  t = twoLeaves();
  t.startLevel = 2;
  t.depth = 1;
  t.rootKeys = {49, 48};
  t.childMasks = {0, 0};
  rejects(t, 1, 6, "not strictly increasing");
  t = twoLeaves();
  t.childMasks = {0b00000101, 0};
  rejects(t, 1, 6, "fewer node masks");
  t = twoLeaves();
  t.childMasks = {0b00000101, 0, 0, 0};
  rejects(t, 1, 6, "more node masks");
}

TEST(SurfaceQuantization, octahedralNormalsAreWithinTheirStep) {
  std::mt19937 rng(3);
  std::normal_distribution<float> g;
  double worst8 = 0.0, worst12 = 0.0;
  for (int i = 0; i < 20000; ++i) {
    std::array<float, 3> n = {g(rng), g(rng), g(rng)};
    const float length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (float& c : n) c /= length;
    for (int bits : {8, 12}) {
      const auto d = decodeOctahedral(encodeOctahedral(n, bits), bits);
      const double angle =
          std::acos(std::min(1.0, double(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]))) * 180.0 / M_PI;
      (bits == 8 ? worst8 : worst12) = std::max(bits == 8 ? worst8 : worst12, angle);
    }
  }
  std::printf("octahedral normals: largest error %.3f° (2x8 bits), %.4f° (2x12 bits)\n", worst8,
              worst12);
  EXPECT_LT(worst8, 1.0);
  EXPECT_LT(worst12, 0.06);
}

TEST(SurfaceQuantization, distancesNeverFlipSign) {
  const AttributeDesc distance{Semantic::SignedDistance, Encoding::Snorm8, 1, 1.0f};
  for (uint8_t level : {0, 5, 12, 20})
    for (double f = -2.0; f <= 2.0; f += 0.0137) {
      const float value = float(f * nodeDiagonal(level));
      const float back = roundTripDistance(value, level, distance);
      EXPECT_FALSE((value > 0 && back < 0) || (value < 0 && back > 0));
      if (std::abs(f) <= 1.0) {
        EXPECT_LE(std::abs(back - value), nodeDiagonal(level) / 254.0 * 1.0001);
      }
    }
}

TEST(SurfacePayload, corruptPayloadsAreRejectedWithTheChunk) {
  const std::vector<std::byte> golden =
      test::readFile(std::filesystem::path(ISO_TEST_DATA_DIR) / "golden-v2.iso");
  const Reader reader = Reader::fromMemory(golden, "golden.iso");
  const uint64_t at = reader.chunk(5).offset;
  struct Case {
    size_t offset;
    std::byte value;
    const char* reason;
  };
  for (const Case& c :
       {Case{4, std::byte{9}, "its header implies"}, Case{8, std::byte{13}, "payload is"},
        Case{18, std::byte{1}, "reserved"}, Case{24, std::byte{7}, "not inside"},
        Case{32, std::byte{0b111}, "node masks"}, Case{16, std::byte{0}, "start level"},
        Case{12, std::byte{0xFF}, "do not fit the payload"}}) {
    std::vector<std::byte> bytes = golden;
    bytes[at + c.offset] = c.value;
    // Keep the payload's checksum right so that only the surface rules can reject it.
    const uint64_t sum = XXH3_64bits(bytes.data() + at, reader.chunk(5).storedSize);
    std::memcpy(bytes.data() + reader.bytes().size() - 64 - reader.metadata().size() - 80 + 24,
                &sum, 8);
    test::resealChecksums(bytes);
    const Reader mutated = Reader::fromMemory(bytes, "mutant.iso");
    try {
      decodeSurfaceChunk(mutated, 5);
      ADD_FAILURE() << "accepted byte " << c.offset;
    } catch (const FileError& error) {
      EXPECT_NE(error.reason().find("chunk 5"), std::string::npos) << error.what();
      EXPECT_NE(error.reason().find(c.reason), std::string::npos) << error.what();
      EXPECT_EQ(error.offset(), at);
    }
    EXPECT_THROW(SurfaceModel::load(mutated), FileError);
  }
}

}  // namespace
}  // namespace iso
