// Points chunks (specs/iso-format.md, "Points chunks"): what is encoded decodes exactly, the
// header's bytes are where the spec says, and every rule a reader checks rejects a file that
// breaks it, naming the file and the chunk.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/points.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "tests/support/support.h"

namespace iso {
namespace {

PointsChunk randomPoints(size_t n, bool colors, bool normals, uint64_t seed) {
  std::mt19937_64 rng(seed);
  PointsChunk c;
  c.stepBits = 27;
  for (size_t i = 0; i < n; ++i) {
    // Offsets around a few clusters, and the extremes of int32.
    const int32_t base = int32_t(rng() % 4) * 1000000;
    c.offsets.push_back({base + int32_t(rng() % 5000), base - int32_t(rng() % 5000),
                         int32_t(rng() % 70000) - 35000});
    if (colors) c.colors.push_back({uint16_t(rng()), uint16_t(rng() % 256 * 257), uint16_t(65535)});
    if (normals) c.normals.push_back({int16_t(rng() % 65535 - 32767), 0, int16_t(-32767)});
  }
  // The widest spans Draco's coder allows.
  c.offsets[0] = {std::numeric_limits<int32_t>::max(), -(int32_t{1} << 30), 0};
  return c;
}

// The points as sorted tuples: Draco's kd-tree coder reorders them.
using Row = std::tuple<std::array<int32_t, 3>, std::array<uint16_t, 3>, std::array<int16_t, 3>>;
std::vector<Row> rowsOf(const PointsChunk& c) {
  std::vector<Row> rows;
  for (size_t i = 0; i < c.size(); ++i)
    rows.emplace_back(c.offsets[i], c.colors.empty() ? std::array<uint16_t, 3>{} : c.colors[i],
                      c.normals.empty() ? std::array<int16_t, 3>{} : c.normals[i]);
  std::sort(rows.begin(), rows.end());
  return rows;
}

FileHeader pointsHeader() {
  FileHeader h;
  h.maxLevel = 5;
  h.frame = {{100.0, -20.0, 3.0}, 8.0};
  return h;
}

ChunkDesc pointsDesc(uint64_t count, uint8_t level = 3, uint64_t key = 0x1a5) {
  ChunkDesc d;
  d.kind = kPointsKind;
  d.level = level;
  d.key = key;
  d.pointCount = count;
  d.codec = Codec::Raw;
  return d;
}

// A file holding one chunk of these bytes and this description.
std::filesystem::path fileWith(const test::TempDir& dir, const std::string& name,
                               const ChunkDesc& desc, const std::vector<std::byte>& data) {
  const auto path = dir / name;
  Writer writer(path, pointsHeader());
  writer.addChunk(desc, data);
  writer.finish();
  return path;
}

TEST(PointsChunk, everyAttributeComesBackExactlyThroughAFile) {
  test::TempDir dir;
  for (const auto& [colors, normals] : {std::pair{false, false}, std::pair{true, false},
                                        std::pair{false, true}, std::pair{true, true}}) {
    SCOPED_TRACE(testing::Message() << "colors " << colors << ", normals " << normals);
    const PointsChunk in = randomPoints(5000, colors, normals, 7);
    const std::vector<std::byte> data = encodePointsChunk(in);
    // The header, byte by byte.
    uint32_t count = 0;
    std::memcpy(&count, data.data(), 4);
    EXPECT_EQ(count, 5000u);
    EXPECT_EQ(uint8_t(data[4]), 27);
    EXPECT_EQ(uint8_t(data[5]), (colors ? 1 : 0) | (normals ? 2 : 0));
    EXPECT_EQ(uint8_t(data[6]) | uint8_t(data[7]), 0);
    EXPECT_EQ(std::memcmp(data.data() + 8, "DRACO", 5), 0);

    const auto path = fileWith(dir, "points.iso", pointsDesc(5000), data);
    const Reader reader = Reader::open(path);
    EXPECT_EQ(chunkKindName(reader.chunk(0).kind), "points");
    const PointsChunk out = decodePointsChunk(reader, 0);
    EXPECT_EQ(out.stepBits, 27);
    EXPECT_EQ(out.colors.size(), colors ? 5000u : 0u);
    EXPECT_EQ(out.normals.size(), normals ? 5000u : 0u);
    EXPECT_EQ(rowsOf(out), rowsOf(in));
    EXPECT_TRUE(verifyFile(reader).ok());
  }
}

TEST(PointsChunk, radiiComeBackExactlyAndTheirCodeRoundsUp) {
  test::TempDir dir;
  PointsChunk in = randomPoints(5000, true, true, 9);
  std::mt19937_64 rng(10);
  for (size_t i = 0; i < in.size(); ++i) in.radii.push_back(uint16_t(rng()));
  const std::vector<std::byte> data = encodePointsChunk(in);
  EXPECT_EQ(uint8_t(data[5]), 1 | 2 | 4);
  const Reader reader = Reader::open(fileWith(dir, "radii.iso", pointsDesc(5000), data));
  const PointsChunk out = decodePointsChunk(reader, 0);
  ASSERT_EQ(out.radii.size(), in.size());
  // Draco reorders the points: match each point's radius by its offsets, colors and normals.
  std::map<Row, std::multiset<uint16_t>> radiusOf;
  for (size_t i = 0; i < in.size(); ++i)
    radiusOf[Row(in.offsets[i], in.colors[i], in.normals[i])].insert(in.radii[i]);
  for (size_t i = 0; i < out.size(); ++i) {
    auto& left = radiusOf[Row(out.offsets[i], out.colors[i], out.normals[i])];
    ASSERT_TRUE(left.contains(out.radii[i])) << "point " << i;
    left.erase(left.find(out.radii[i]));
  }
  EXPECT_TRUE(verifyFile(reader).ok());
  // The code: 2^(-code / 1024) frame units, the radius it stores never below the one given and
  // less than one step (2^(1/1024)) above it.
  for (const double r : {1.0, 0.5, 0.3, 1e-3, 7.77e-6, 0x1p-64}) {
    const double stored = decodePointRadius(encodePointRadius(r));
    EXPECT_GE(stored, r) << r;
    EXPECT_LE(stored, r * std::exp2(1.0 / 1024.0)) << r;
  }
  EXPECT_EQ(encodePointRadius(2.0), 0);  // clamped to the frame
  EXPECT_EQ(decodePointRadius(1024), 0.5);
  EXPECT_EQ(encodePointRadius(1e-30), 65535);
}

TEST(PointsChunk, aPointsChunksParentMustBeAPointsChunk) {
  test::TempDir dir;
  const std::vector<std::byte> good = encodePointsChunk(randomPoints(300, false, false, 3));
  const auto path = dir / "parent.iso";
  {
    Writer writer(path, pointsHeader());
    ChunkDesc blob;
    blob.level = 2;
    blob.key = 0x1a5 >> 3;
    const uint32_t parent = writer.addChunk(blob, good);
    ChunkDesc child = pointsDesc(300);
    child.parent = parent;
    writer.addChunk(child, good);
    writer.finish();
  }
  try {
    Reader::open(path);
    ADD_FAILURE() << "opened";
  } catch (const FileError& error) {
    EXPECT_NE(error.reason().find("is not a points chunk"), std::string::npos) << error.what();
  }
}

TEST(PointsChunk, eightBitColorsTravelAsBytesAndComeBackExactly) {
  // Colors that are all 257 · (8-bit code) are coded as bytes; one that is not sends the whole
  // chunk's colors as 16-bit values, which cost the coder 8 more bits a channel.
  test::TempDir dir;
  PointsChunk eight = randomPoints(5000, true, false, 11);
  std::mt19937_64 rng(12);
  for (std::array<uint16_t, 3>& c : eight.colors)
    for (uint16_t& v : c) v = uint16_t(rng() % 256 * 257);
  PointsChunk sixteen = eight;
  sixteen.colors[17][1] += 1;
  const std::vector<std::byte> bytes = encodePointsChunk(eight), wide = encodePointsChunk(sixteen);
  EXPECT_LT(bytes.size() + 5000 * 2, wide.size()) << bytes.size() << " against " << wide.size();
  for (const PointsChunk* in : {&eight, &sixteen}) {
    const Reader reader =
        Reader::open(fileWith(dir, "colors.iso", pointsDesc(5000), encodePointsChunk(*in)));
    EXPECT_EQ(rowsOf(decodePointsChunk(reader, 0)), rowsOf(*in));
  }
}

TEST(PointsChunk, positionsAreTheCellCornerPlusStepsExactly) {
  // Cell (level 3, key 0x1a5 = 0b110'100'101): bit 3j of the key is bit j of x, 3j+1 of y, 3j+2
  // of z, so x = 0b001 = 1, y = 0b100 = 4, z = 0b111 = 7.
  const std::array<double, 3> p = pointFramePosition(3, 0x1a5, 10, {1024, -3, 7});
  EXPECT_EQ(p[0], 1.0 / 8.0 + 1.0);
  EXPECT_EQ(p[1], 4.0 / 8.0 - 3.0 / 1024.0);
  EXPECT_EQ(p[2], 7.0 / 8.0 + 7.0 / 1024.0);
  const std::array<double, 3> fine = pointFramePosition(0, 0, 52, {1, 0, -1});
  EXPECT_EQ(fine[0], std::ldexp(1.0, -52));
  EXPECT_EQ(fine[2], -std::ldexp(1.0, -52));
}

TEST(PointsChunk, theEncoderRefusesWhatTheFormatDoesNotAllow) {
  PointsChunk empty;
  EXPECT_THROW(encodePointsChunk(empty), InternalError);
  PointsChunk c = randomPoints(10, true, false, 1);
  c.colors.pop_back();
  EXPECT_THROW(encodePointsChunk(c), InternalError);
  c = randomPoints(10, false, false, 1);
  c.stepBits = 53;
  EXPECT_THROW(encodePointsChunk(c), InternalError);
  c = randomPoints(10, false, false, 1);
  c.offsets[1][2] = std::numeric_limits<int32_t>::max();
  c.offsets[2][2] = -1;  // a span of 2^31
  EXPECT_THROW(encodePointsChunk(c), InternalError);
}

// Decoding throws a FileError naming the file, chunk 0 and `reason`; verification reports it.
void expectRejected(const std::filesystem::path& path, const std::string& reason) {
  SCOPED_TRACE(reason);
  const Reader reader = Reader::open(path);
  try {
    decodePointsChunk(reader, 0);
    ADD_FAILURE() << "decoded";
  } catch (const FileError& error) {
    EXPECT_NE(std::string(error.what()).find(path.filename().string()), std::string::npos)
        << error.what();
    EXPECT_NE(std::string(error.what()).find("chunk 0"), std::string::npos) << error.what();
    EXPECT_NE(error.reason().find(reason), std::string::npos) << error.what();
  }
  const VerifyResult verified = verifyFile(reader);
  ASSERT_EQ(verified.problems.size(), 1u);
  EXPECT_NE(verified.problems[0].reason.find(reason), std::string::npos);
}

// Opening throws a FileError naming the file, chunk 0's table entry and `reason`: the entry
// breaks a rule of points chunks that the table alone shows.
void expectRefusedAtOpen(const std::filesystem::path& path, const std::string& reason,
                         uint32_t field) {
  SCOPED_TRACE(reason);
  try {
    Reader::open(path);
    ADD_FAILURE() << "opened";
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), path.string());
    EXPECT_NE(error.reason().find("chunk 0: " + reason), std::string::npos) << error.what();
    const uint64_t table = std::filesystem::file_size(path) - 64 - 2 - 80;  // metadata "{}"
    EXPECT_EQ(error.offset(), table + field) << error.what();
  }
}

TEST(PointsChunk, tableEntriesThatBreakTheRulesAreRefusedAtOpen) {
  test::TempDir dir;
  const std::vector<std::byte> good = encodePointsChunk(randomPoints(300, true, true, 3));
  expectRefusedAtOpen(fileWith(dir, "zero.iso", pointsDesc(0), good),
                      "a points chunk holds 1 to 1048576 points, not 0", 40);
  expectRefusedAtOpen(fileWith(dir, "many.iso", pointsDesc(uint64_t{1} << 21), good),
                      "a points chunk holds 1 to 1048576 points, not 2097152", 40);
  expectRefusedAtOpen(fileWith(dir, "huge.iso", pointsDesc(~uint64_t{0}), good),
                      "a points chunk holds 1 to 1048576 points, not 18446744073709551615", 40);
  ChunkDesc withNodes = pointsDesc(300);
  withNodes.nodeCount = 1;
  expectRefusedAtOpen(fileWith(dir, "nodes.iso", withNodes, good), "a points chunk has nodes", 56);
  ChunkDesc withLeaves = pointsDesc(300);
  withLeaves.leafCount = 1;
  expectRefusedAtOpen(fileWith(dir, "leaves.iso", withLeaves, good), "a points chunk has leaves",
                      60);
}

TEST(PointsChunk, hostileChunksAreRejectedWithTheirReason) {
  test::TempDir dir;
  const PointsChunk in = randomPoints(300, true, true, 3);
  const std::vector<std::byte> good = encodePointsChunk(in);
  {
    const Reader reader = Reader::open(fileWith(dir, "good.iso", pointsDesc(300), good));
    ASSERT_EQ(rowsOf(decodePointsChunk(reader, 0)), rowsOf(in));
  }
  const auto with = [&](size_t at, uint8_t value) {
    std::vector<std::byte> bytes = good;
    bytes[at] = std::byte{value};
    return bytes;
  };
  expectRejected(fileWith(dir, "count.iso", pointsDesc(301), good), "the chunk table 301");
  expectRejected(fileWith(dir, "step.iso", pointsDesc(300), with(4, 53)), "step bits 53");
  expectRejected(fileWith(dir, "flags.iso", pointsDesc(300), with(5, 8)), "reserved");
  expectRejected(fileWith(dir, "reserved.iso", pointsDesc(300), with(7, 1)), "reserved");
  // The header claims attributes the Draco cloud lacks, or lacks ones it has.
  expectRejected(fileWith(dir, "fewer.iso", pointsDesc(300), with(5, 1)), "3 attributes");
  const std::vector<std::byte> plain = encodePointsChunk(randomPoints(300, false, false, 3));
  std::vector<std::byte> claims = plain;
  claims[5] = std::byte{1};
  expectRejected(fileWith(dir, "claims.iso", pointsDesc(300), claims), "1 attributes");
  // The Draco count is not the chunk's: both counts of ours say 299.
  std::vector<std::byte> fewer = good;
  fewer[0] = std::byte{43};  // 300 = 0x12c
  expectRejected(fileWith(dir, "draco-count.iso", pointsDesc(299), fewer), "Draco point count");
  expectRejected(fileWith(dir, "short.iso", pointsDesc(300),
                          std::vector<std::byte>(good.begin(), good.begin() + 8)),
                 "shorter than its header");
  expectRejected(fileWith(dir, "not-draco.iso", pointsDesc(300), with(8, 'X')),
                 "not a Draco kd-tree point cloud");
  expectRejected(fileWith(dir, "truncated.iso", pointsDesc(300),
                          std::vector<std::byte>(good.begin(), good.end() - 40)),
                 "Draco cannot decode");
  // Random bytes after a valid Draco header: Draco fails (or decodes garbage that breaks a rule);
  // it never crashes or hangs.
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::byte> bytes = good;
    for (int flips = 0; flips < 1 + trial % 4; ++flips) {
      const size_t at = 8 + 15 + rng() % (bytes.size() - 23);
      bytes[at] ^= std::byte(uint8_t(1u << (rng() % 8)));
    }
    const auto path = fileWith(dir, "flipped.iso", pointsDesc(300), bytes);
    const Reader reader = Reader::open(path);
    try {
      const PointsChunk out = decodePointsChunk(reader, 0);
      EXPECT_EQ(out.size(), 300u);  // what decodes keeps every rule
      EXPECT_EQ(out.colors.size(), 300u);
    } catch (const FileError& error) {
      EXPECT_NE(std::string(error.what()).find("chunk 0"), std::string::npos);
    }
  }
}

TEST(PointsChunk, sequentialDracoIsNotAPointsChunk) {
  // Only the kd-tree method is allowed: one coder for every reader to support.
  test::TempDir dir;
  std::vector<std::byte> good = encodePointsChunk(randomPoints(100, false, false, 9));
  // Draco header: "DRACO", version major, minor, encoder type, encoder method (0: sequential).
  ASSERT_EQ(uint8_t(good[8 + 8]), 1);  // kd-tree
  good[8 + 8] = std::byte{0};
  expectRejected(fileWith(dir, "sequential.iso", pointsDesc(100), good),
                 "not a Draco kd-tree point cloud");
}

}  // namespace
}  // namespace iso
