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
  const auto write = [&](uint32_t parent) {
    Writer writer(path, pointsHeader());
    ChunkDesc blob;
    blob.level = 2;
    blob.key = 0x1a5 >> 3;
    writer.addChunk(blob, good);
    ChunkDesc child = pointsDesc(300);
    child.parent = parent;
    writer.addChunk(child, good);
    writer.finish();
  };
  // The writer refuses the link, the reader refuses it in the table.
  try {
    write(0);
    ADD_FAILURE() << "written";
  } catch (const InternalError& error) {
    EXPECT_NE(std::string(error.what()).find("chunk 1: parent 0 is not a points chunk"),
              std::string::npos)
        << error.what();
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  write(kNoParent);
  test::writeFile(
      path, test::withChangedEntry(test::readFile(path), 1, [](ChunkInfo& c) { c.parent = 0; }));
  try {
    Reader::open(path);
    ADD_FAILURE() << "opened";
  } catch (const FileError& error) {
    EXPECT_NE(error.reason().find("chunk 1: parent 0 is not a points chunk"), std::string::npos)
        << error.what();
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

// A file holding one chunk of these bytes whose entry has the counts `desc` gives, which break a
// rule of points chunks: the writer refuses to write it (naming the rule), so it is written with
// 300 points and the entry changed.
std::filesystem::path fileWithRefusedEntry(const test::TempDir& dir, const std::string& name,
                                           const ChunkDesc& desc,
                                           const std::vector<std::byte>& data,
                                           const std::string& reason) {
  try {
    fileWith(dir, name, desc, data);
    ADD_FAILURE() << "written";
  } catch (const InternalError& error) {
    EXPECT_NE(std::string(error.what()).find("chunk 0: " + reason), std::string::npos)
        << error.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / name));
  const auto path = fileWith(dir, name, pointsDesc(300, desc.level, desc.key), data);
  test::writeFile(path, test::withChangedEntry(test::readFile(path), 0, [&](ChunkInfo& c) {
                    c.pointCount = desc.pointCount;
                    c.nodeCount = desc.nodeCount;
                    c.leafCount = desc.leafCount;
                  }));
  return path;
}

TEST(PointsChunk, tableEntriesThatBreakTheRulesAreRefusedAtOpen) {
  test::TempDir dir;
  const std::vector<std::byte> good = encodePointsChunk(randomPoints(300, true, true, 3));
  const auto refused = [&](const std::string& name, const ChunkDesc& desc,
                           const std::string& reason, uint32_t field) {
    expectRefusedAtOpen(fileWithRefusedEntry(dir, name, desc, good, reason), reason, field);
  };
  refused("zero.iso", pointsDesc(0), "a points chunk holds 1 to 1048576 points, not 0", 40);
  refused("many.iso", pointsDesc(uint64_t{1} << 21),
          "a points chunk holds 1 to 1048576 points, not 2097152", 40);
  refused("huge.iso", pointsDesc(~uint64_t{0}),
          "a points chunk holds 1 to 1048576 points, not 18446744073709551615", 40);
  ChunkDesc withNodes = pointsDesc(300);
  withNodes.nodeCount = 1;
  refused("nodes.iso", withNodes, "a points chunk has nodes", 56);
  ChunkDesc withLeaves = pointsDesc(300);
  withLeaves.leafCount = 1;
  refused("leaves.iso", withLeaves, "a points chunk has leaves", 60);
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


// Since 2.1: values chunks. A file of one points chunk (id 0) and its values chunk (id 1).
std::filesystem::path fileWithValues(const test::TempDir& dir, const std::string& name,
                                     const std::vector<std::byte>& points, uint64_t count,
                                     const std::vector<std::byte>& values,
                                     ChunkDesc valuesDesc) {
  const auto path = dir / name;
  Writer writer(path, pointsHeader());
  writer.addChunk(pointsDesc(count), points);
  writer.addChunk(valuesDesc, values);
  writer.finish();
  return path;
}

ChunkDesc valuesDesc(uint64_t count) {
  ChunkDesc d = pointsDesc(count);
  d.kind = kValuesKind;
  d.codec = Codec::Zstd;
  return d;
}

TEST(ValuesChunk, eachPointGetsItsOwnValueBackThroughAFileThoughDracoReordersThePoints) {
  test::TempDir dir;
  PointsChunk in = randomPoints(5000, true, true, 21);
  for (size_t i = 0; i < 40; ++i) in.offsets[4000 + i] = in.offsets[10];  // same places
  std::mt19937_64 rng(22);
  std::vector<double> values(in.size());
  for (double& v : values) v = double(rng() % 60001);  // an intensity: kept exactly
  values[3] = std::nan("");                              // no value
  const std::vector<std::byte> data = encodePointsChunk(in);
  const std::vector<uint32_t> order = decodedPointOrder(data, in);
  std::vector<double> inDecodedOrder(order.size());
  for (size_t i = 0; i < order.size(); ++i) inDecodedOrder[i] = values[order[i]];
  const PointValues quantized = quantizeValues("intensity", 0, inDecodedOrder);
  EXPECT_EQ(quantized.step, 1.0);
  const auto path =
      fileWithValues(dir, "values.iso", data, in.size(), encodeValuesChunk(quantized),
                     valuesDesc(in.size()));
  const Reader reader = Reader::open(path);
  EXPECT_TRUE(verifyFile(reader).ok());
  const PointsChunk out = decodePointsChunk(reader, 0);
  const PointValues back = decodeValuesChunk(reader, 1);
  EXPECT_EQ(back.name, "intensity");
  EXPECT_EQ(back.pointsChunk, 0u);
  ASSERT_EQ(back.size(), in.size());
  // Each decoded point's value is the value of an input point alike in every attribute, each
  // input point's value used once.
  std::map<Row, std::multiset<double>> valuesOf;
  for (size_t i = 0; i < in.size(); ++i)
    valuesOf[Row(in.offsets[i], in.colors[i], in.normals[i])].insert(
        std::isnan(values[i]) ? -1.0 : values[i]);
  size_t missing = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    const double v = back.value(i);
    missing += std::isnan(v) ? 1 : 0;
    auto& left = valuesOf[Row(out.offsets[i], out.colors[i], out.normals[i])];
    const double key = std::isnan(v) ? -1.0 : v;
    ASSERT_TRUE(left.contains(key)) << "point " << i << " value " << v;
    left.erase(left.find(key));
  }
  EXPECT_EQ(missing, 1u);
}

TEST(ValuesChunk, valuesThatAreNotSmallIntegersKeepHalfAStep) {
  std::vector<double> values;
  for (int i = 0; i < 1000; ++i) values.push_back(3.0e8 + 17.123456 * i);  // GPS times
  values.push_back(-std::numeric_limits<double>::infinity());
  const PointValues q = quantizeValues("gps_time", 5, values);
  EXPECT_EQ(q.offset, 3.0e8);
  EXPECT_TRUE(q.missing);
  EXPECT_NEAR(q.step, 17.123456 * 999 / 65534, 1e-9);
  for (size_t i = 0; i < 1000; ++i) EXPECT_LE(std::abs(q.value(i) - values[i]), q.step / 2 + 1e-6);
  EXPECT_EQ(q.codes[1000], kNoValue);
  // One value: step 1, code 0. Integers spanning more than 65534: a step above 1.
  EXPECT_EQ(quantizeValues("v", 0, std::vector<double>{2.5}).value(0), 2.5);
  const PointValues wide = quantizeValues("v", 0, std::vector<double>{0.0, 70000.0});
  EXPECT_GT(wide.step, 1.0);
  EXPECT_EQ(wide.value(1), 70000.0);
  // Every 16-bit value, none missing: all 65536 codes are values, kept exactly.
  std::vector<double> all(65536);
  for (size_t i = 0; i < all.size(); ++i) all[i] = double(65535 - i);
  const PointValues full = quantizeValues("intensity", 0, all);
  EXPECT_FALSE(full.missing);
  EXPECT_EQ(full.step, 1.0);
  for (size_t i = 0; i < all.size(); ++i) ASSERT_EQ(full.value(i), all[i]);
  EXPECT_THROW(quantizeValues("", 0, values), InternalError);
  EXPECT_THROW(quantizeValues(std::string(33, 'a'), 0, values), InternalError);
  EXPECT_THROW(quantizeValues("v", 0, std::vector<double>{}), InternalError);
}

TEST(ValuesChunk, bytesAreWhereTheSpecSays) {
  const PointValues v = quantizeValues("classification", 9, std::vector<double>{2.0, 6.0, 2.0});
  const std::vector<std::byte> b = encodeValuesChunk(v);
  ASSERT_EQ(b.size(), 64u + 3 * 2);
  const auto u32 = [&](size_t at) { uint32_t x; std::memcpy(&x, b.data() + at, 4); return x; };
  const auto f64 = [&](size_t at) { double x; std::memcpy(&x, b.data() + at, 8); return x; };
  const auto u16 = [&](size_t at) { uint16_t x; std::memcpy(&x, b.data() + at, 2); return x; };
  EXPECT_EQ(u32(0), 9u);  // pointsChunk
  EXPECT_EQ(u32(4), 3u);  // count
  EXPECT_EQ(f64(8), 2.0);  // offset
  EXPECT_EQ(f64(16), 1.0);  // step
  for (size_t i = 24; i < 32; ++i) EXPECT_EQ(b[i], std::byte{0});  // flags, reserved
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(b.data() + 32)), "classification");
  for (size_t i = 32 + 14; i < 64; ++i) EXPECT_EQ(b[i], std::byte{0});  // name padding
  EXPECT_EQ(u16(64), 0);
  EXPECT_EQ(u16(66), 4);
  EXPECT_EQ(u16(68), 0);
}

TEST(ValuesChunk, valuesThatBreakTheRulesAreRefusedWithTheirReason) {
  test::TempDir dir;
  const PointsChunk in = randomPoints(100, false, false, 4);
  const std::vector<std::byte> points = encodePointsChunk(in);
  const std::vector<double> values(100, 1.0);
  const std::vector<std::byte> good = encodeValuesChunk(quantizeValues("v", 0, values));
  const auto expectRefused = [&](const std::string& name, const std::vector<std::byte>& bytes,
                                 ChunkDesc desc, const std::string& reason) {
    SCOPED_TRACE(reason);
    const Reader reader = Reader::open(fileWithValues(dir, name, points, 100, bytes, desc));
    try {
      decodeValuesChunk(reader, 1);
      ADD_FAILURE() << "decoded";
    } catch (const FileError& error) {
      EXPECT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
      EXPECT_EQ(error.reason().rfind("chunk 1: ", 0), 0u) << error.what();
      EXPECT_NE(error.reason().find(reason), std::string::npos) << error.what();
    }
    const VerifyResult verified = verifyFile(reader);
    ASSERT_EQ(verified.problems.size(), 1u);
    EXPECT_EQ(verified.problems[0].chunk, 1u);
  };
  const auto with = [&](size_t at, std::initializer_list<uint8_t> bytes) {
    std::vector<std::byte> b = good;
    for (uint8_t x : bytes) b[at++] = std::byte{x};
    return b;
  };
  {
    const Reader reader = Reader::open(fileWithValues(dir, "good.iso", points, 100, good,
                                                      valuesDesc(100)));
    EXPECT_EQ(decodeValuesChunk(reader, 1).value(99), 1.0);
  }
  expectRefused("self.iso", with(0, {1}), valuesDesc(100), "which is not a points chunk");
  expectRefused("missing.iso", with(0, {7}), valuesDesc(100), "which is not a points chunk");
  ChunkDesc other = valuesDesc(99);
  expectRefused("count.iso", good, other, "values header says 100 values, the chunk table 99");
  ChunkDesc elsewhere = valuesDesc(100);
  elsewhere.key = 0x1a4;
  expectRefused("cell.iso", good, elsewhere, "cell is not its points chunk's");
  expectRefused("flags.iso", with(24, {2}), valuesDesc(100), "reserved values header bits");
  expectRefused("reserved.iso", with(25, {1}), valuesDesc(100), "reserved");
  expectRefused("padding.iso", with(40, {'x'}), valuesDesc(100), "padding is not zero");
  expectRefused("name.iso", with(32, {0}), valuesDesc(100), "the value name is empty");
  expectRefused("step.iso", with(16, {0, 0, 0, 0, 0, 0, 0, 0}), valuesDesc(100),
                "step is not positive");
  expectRefused("nan.iso", with(8, {0, 0, 0, 0, 0, 0, 0xF8, 0x7F}), valuesDesc(100),
                "not finite");
  expectRefused("short.iso", std::vector<std::byte>(good.begin(), good.end() - 2),
                valuesDesc(100), "not its header and 2 bytes a value");
  // Entry rules, at open: a parent (values chunks have none). The writer refuses to write it; in
  // the table, opening refuses it.
  ChunkDesc parented = valuesDesc(100);
  parented.parent = 0;
  parented.level = 4;
  parented.key = 0x1a5 << 3;
  try {
    fileWithValues(dir, "parent.iso", points, 100, good, parented);
    ADD_FAILURE() << "written";
  } catch (const InternalError& error) {
    EXPECT_NE(std::string(error.what()).find("chunk 1: a values chunk of this kind has no parent"),
              std::string::npos)
        << error.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "parent.iso"));
  parented.parent = kNoParent;
  const auto path = fileWithValues(dir, "parent.iso", points, 100, good, parented);
  test::writeFile(
      path, test::withChangedEntry(test::readFile(path), 1, [](ChunkInfo& c) { c.parent = 0; }));
  try {
    Reader::open(path);
    ADD_FAILURE() << "opened";
  } catch (const FileError& error) {
    EXPECT_NE(error.reason().find("chunk 1: a values chunk of this kind has no parent"),
              std::string::npos)
        << error.what();
  }
}

TEST(ValuesChunk, volumePointsAreReadAsPointsAndAreNotAPointsChunksParent) {
  test::TempDir dir;
  const PointsChunk in = randomPoints(200, true, false, 6);
  ChunkDesc volume = pointsDesc(200);
  volume.kind = kVolumePointsKind;
  const Reader reader = Reader::open(fileWith(dir, "volume.iso", volume, encodePointsChunk(in)));
  EXPECT_EQ(rowsOf(decodePointsChunk(reader, 0)), rowsOf(in));
  EXPECT_EQ(chunkKindName(reader.chunk(0).kind), "volume points");
  EXPECT_TRUE(verifyFile(reader).ok());
}

}  // namespace
}  // namespace iso
