// The LAZ reader on LASzip-compressed files against the LAS files they decompress to
// (tests/data/laz/README.md says how each was made): point formats 0–3 and 6–8, LAS 1.0–1.4,
// fixed and variable chunks, the chunk table's offset at the end of the file, extra bytes,
// coordinate systems in VLRs and EVLRs, a tile of a published scan; readers opened together;
// what laz-perf does not decode; damaged chunk tables, lying counts, damaged chunks, truncation.
#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/las_format.h"
#include "pipeline/io/laz_chunks.h"
#include "pipeline/io/laz_decoder.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

constexpr const char* kSamples[] = {
    "las10-f0-chunks100",     "las11-f1-geotiff",    "las12-f2-variable",   "las13-f3-onechunk",
    "las14-f6-variable-evlr", "las14-f7-extrabytes", "las14-f8-tableatend", "lion-tile-r006"};

constexpr size_t kPointDataOffsetAt = 96;
constexpr size_t kPointFormatAt = 104;
constexpr size_t kRecordLengthAt = 105;
constexpr size_t kLegacyCountAt = 107;

std::filesystem::path sample(const std::string& name) {
  return std::filesystem::path(ISO_TEST_DATA_DIR) / "laz" / name;
}

PointCloud readAll(const std::filesystem::path& path, size_t batch = 1000) {
  return test::readInBatches(path, {.columns = "", .keepExtras = true}, nullptr, batch);
}

void expectSamePoints(const PointCloud& a, const PointCloud& b) {
  ASSERT_EQ(a.size(), b.size());
  EXPECT_TRUE(a.positions == b.positions);
  EXPECT_TRUE(a.colors == b.colors);
  EXPECT_EQ(a.extraNames, b.extraNames);
  EXPECT_TRUE(a.extras == b.extras);
}

template <typename T>
T loadAt(const std::vector<std::byte>& bytes, size_t at) {
  T value;
  std::memcpy(&value, bytes.data() + at, sizeof value);
  return value;
}

template <typename T>
void storeAt(std::vector<std::byte>& bytes, size_t at, T value) {
  std::memcpy(bytes.data() + at, &value, sizeof value);
}

// A copy of `bytes` with `value` at `at`.
template <typename T>
std::vector<std::byte> patched(std::vector<std::byte> bytes, size_t at, T value) {
  storeAt(bytes, at, value);
  return bytes;
}

// Where the payload of the LASzip VLR starts.
size_t laszipPayloadAt(const std::vector<std::byte>& bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const size_t user = text.find("laszip encoded");
  EXPECT_NE(user, std::string_view::npos);
  return user - 2 + 54;
}

uint64_t chunkTableAt(const std::vector<std::byte>& bytes) {
  const int64_t at = loadAt<int64_t>(bytes, loadAt<uint32_t>(bytes, kPointDataOffsetAt));
  return at == -1 ? loadAt<uint64_t>(bytes, bytes.size() - 8) : uint64_t(at);
}

// The error reading `bytes` as a LAZ file gives ("" when none).
std::string lazError(const std::vector<std::byte>& bytes, const std::string& name = "d.laz") {
  test::TempDir dir;
  test::writeFile(dir / name, bytes);
  return test::readError(dir / name);
}

#define EXPECT_CONTAINS(text, part) EXPECT_NE((text).find(part), std::string::npos) << (text)

class LazReader : public testing::Test {
 protected:
  void SetUp() override {
    if (!io::hasLazDecoder()) GTEST_SKIP() << io::kLazDecoderMissing;
  }
};

TEST_F(LazReader, everySampleGivesThePointsColorsIntensityAndCoordinateSystemOfItsLas) {
  for (const char* name : kSamples) {
    SCOPED_TRACE(name);
    const auto laz = openPointFile(sample(std::string(name) + ".laz"));
    const auto las = openPointFile(sample(std::string(name) + ".las.gz"));
    EXPECT_EQ(laz->info().format, "laz" + las->info().format.substr(3));
    EXPECT_EQ(laz->info().declaredPoints, las->info().declaredPoints);
    EXPECT_EQ(laz->info().hasColors, las->info().hasColors);
    ASSERT_EQ(laz->info().crs.has_value(), las->info().crs.has_value());
    if (las->info().crs) {
      EXPECT_EQ(laz->info().crs->wkt, las->info().crs->wkt);
      EXPECT_EQ(laz->info().crs->epsg, las->info().crs->epsg);
      EXPECT_EQ(laz->info().crs->source, las->info().crs->source);
    }
    const PointCloud expected = readAll(sample(std::string(name) + ".las.gz"));
    EXPECT_GT(expected.size(), 600u);
    EXPECT_EQ(expected.extraNames,
              io::lasExtraNames(std::stoi(las->info().format.substr(15))));
    expectSamePoints(readAll(sample(std::string(name) + ".laz"), 97), expected);
  }
}

TEST_F(LazReader, theSamplesCoverEveryDecodedFormatChunkingAndCoordinateSystemRecord) {
  std::vector<std::string> formats;
  for (const char* name : kSamples)
    formats.push_back(openPointFile(sample(std::string(name) + ".laz"))->info().format);
  for (const char* format :
       {"laz 1.0 format 0", "laz 1.1 format 1", "laz 1.2 format 2", "laz 1.3 format 3",
        "laz 1.4 format 6", "laz 1.4 format 7", "laz 1.4 format 8"})
    EXPECT_NE(std::find(formats.begin(), formats.end(), format), formats.end()) << format;
  // Variable chunks, the table's offset at the end, the WKT in an EVLR, extra bytes.
  const auto variable = test::readFile(sample("las12-f2-variable.laz"));
  EXPECT_EQ(loadAt<uint32_t>(variable, laszipPayloadAt(variable) + 12), io::kLazVariableChunkSize);
  const auto atEnd = test::readFile(sample("las14-f8-tableatend.laz"));
  EXPECT_EQ(loadAt<int64_t>(atEnd, loadAt<uint32_t>(atEnd, kPointDataOffsetAt)), -1);
  EXPECT_CONTAINS(openPointFile(sample("las14-f6-variable-evlr.laz"))->info().crs->source,
                  "EVLR LASF_Projection 2112");
  EXPECT_EQ(loadAt<uint16_t>(test::readFile(sample("las14-f7-extrabytes.laz")), kRecordLengthAt),
            36 + 3);
}

TEST_F(LazReader, readsTheSamePointsInAnyBatchSize) {
  const PointCloud expected = readAll(sample("las12-f2-variable.las.gz"));
  for (size_t batch : {size_t{1}, size_t{7}, size_t{300}, size_t{1} << 20})
    expectSamePoints(readAll(sample("las12-f2-variable.laz"), batch), expected);
}

TEST_F(LazReader, readersOpenedTogetherGetTheirOwnPointsWhateverTheOrderOfReading) {
  std::vector<std::unique_ptr<PointReader>> readers;
  for (const char* name : kSamples)
    readers.push_back(
        openPointFile(sample(std::string(name) + ".laz"), {.columns = "", .keepExtras = true}));
  // Drop two before reading anything and one half read: their queued chunks are cancelled.
  readers[1].reset();
  PointCloud half;
  readers[5]->read(half, 100);
  readers[5].reset();
  readers[6].reset();
  std::vector<PointCloud> clouds(readers.size());
  for (bool isAnyLeft = true; isAnyLeft;) {  // the last opened first, 50 points each in turn
    isAnyLeft = false;
    for (size_t i = readers.size(); i-- > 0;)
      if (readers[i] && readers[i]->read(clouds[i], 50) > 0) isAnyLeft = true;
  }
  for (size_t i = 0; i < readers.size(); ++i) {
    if (!readers[i]) continue;
    SCOPED_TRACE(kSamples[i]);
    expectSamePoints(clouds[i], readAll(sample(std::string(kSamples[i]) + ".las.gz")));
  }
}

TEST_F(LazReader, thePublishedLionTilesAreExactlyThePointsOfTheMergedLas) {
  const std::filesystem::path data(ISO_SHARED_DATA_DIR);
  if (!std::filesystem::is_directory(data / "lion_laz"))
    GTEST_SKIP() << "no shared data folder at " << data;
  std::vector<std::filesystem::path> tiles;
  for (const auto& entry : std::filesystem::directory_iterator(data / "lion_laz"))
    tiles.push_back(entry.path());
  ASSERT_EQ(tiles.size(), 200u);
  using Point = std::tuple<double, double, double, float, float, float, float>;
  const auto points = [](const PointCloud& c, std::vector<Point>& to) {
    for (size_t i = 0; i < c.size(); ++i)
      to.emplace_back(c.positions[i].x, c.positions[i].y, c.positions[i].z, c.colors[i].r,
                      c.colors[i].g, c.colors[i].b, c.extras[i * c.extraCount()]);
  };
  std::vector<Point> fromTiles, fromLas;
  for (const auto& tile : tiles) points(readAll(tile), fromTiles);
  points(readAll(data / "lion_rgb.las"), fromLas);
  ASSERT_EQ(fromTiles.size(), 341989u);
  std::sort(fromTiles.begin(), fromTiles.end());
  std::sort(fromLas.begin(), fromLas.end());
  EXPECT_TRUE(fromTiles == fromLas);
}

TEST_F(LazReader, refusesByNameWhatLazPerfDoesNotDecode) {
  const auto good = test::readFile(sample("las10-f0-chunks100.laz"));
  const size_t vlr = laszipPayloadAt(good);
  EXPECT_CONTAINS(lazError(patched(good, vlr, uint16_t{1})),
                  "LASzip compressor 1 (pointwise, without chunks) is not decoded: laz-perf "
                  "decodes chunked LAZ");
  EXPECT_CONTAINS(lazError(patched(good, vlr + 2, uint16_t{1})), "unknown LASzip coder 1");
  EXPECT_CONTAINS(lazError(patched(good, vlr + 34 + 4, uint16_t{1})),
                  "LASzip item POINT10 version 1 is not decoded: laz-perf decodes version 2");
  EXPECT_CONTAINS(lazError(patched(good, vlr + 34 + 2, uint16_t{21})),
                  "LASzip item 1 is POINT10 of 21 bytes where point format 0 (record of 20 "
                  "bytes) has POINT10 of 20");
  EXPECT_CONTAINS(lazError(patched(good, vlr - 54 + 2, uint8_t{'X'})),
                  "no LASzip VLR (user \"laszip encoded\", record 22204): not LAZ");
  auto waveform = patched(good, kPointFormatAt, uint8_t{0x84});
  storeAt(waveform, kRecordLengthAt, uint16_t{57});
  EXPECT_CONTAINS(lazError(waveform),
                  "LAZ point format 4 (with waveform packets) is not decoded: laz-perf decodes "
                  "point formats 0-3 and 6-8");
}

TEST_F(LazReader, damagedChunkTablesAreRefusedNamingTheTable) {
  const auto good = test::readFile(sample("las10-f0-chunks100.laz"));
  const uint32_t pointData = loadAt<uint32_t>(good, kPointDataOffsetAt);
  const uint64_t table = chunkTableAt(good);
  EXPECT_CONTAINS(lazError(patched(good, pointData, int64_t{1})),
                  "damaged chunk table: its offset 1 lies outside");
  EXPECT_CONTAINS(lazError(patched(good, pointData, int64_t(good.size()))),
                  "damaged chunk table: its offset");
  EXPECT_CONTAINS(lazError(patched(good, table, uint32_t{7})),
                  "damaged chunk table: unknown version 7 (LASzip writes 0)");
  EXPECT_CONTAINS(lazError(patched(good, table + 4, uint32_t{0})),
                  "damaged chunk table: it lists 0 chunks, but 684 points in chunks of 100 take 7");
  EXPECT_CONTAINS(lazError(patched(good, table + 4, uint32_t{0xFFFFFFFF})),
                  "damaged chunk table: 4294967295 chunks in");
  auto scrambled = good;
  std::fill(scrambled.begin() + ptrdiff_t(table + 8), scrambled.end(), std::byte{0xFF});
  EXPECT_CONTAINS(lazError(scrambled), "damaged chunk table:");
  const std::vector<std::byte> cut(good.begin(), good.begin() + ptrdiff_t(table + 10));
  EXPECT_CONTAINS(lazError(cut), "damaged chunk table: the file ends inside entry");
}

TEST_F(LazReader, pointCountsThatLieAreRefused) {
  // Chunks of a fixed size hold no count: a count that needs other chunks is refused.
  auto fixed = test::readFile(sample("las10-f0-chunks100.laz"));
  storeAt(fixed, kLegacyCountAt, uint32_t{550});
  EXPECT_CONTAINS(lazError(fixed), "it lists 7 chunks, but 550 points in chunks of 100 take 6");
  storeAt(fixed, kLegacyCountAt, uint32_t{800});
  EXPECT_CONTAINS(lazError(fixed), "it lists 7 chunks, but 800 points in chunks of 100 take 8");
  auto variable = test::readFile(sample("las12-f2-variable.laz"));
  storeAt(variable, kLegacyCountAt, uint32_t{800});
  EXPECT_CONTAINS(lazError(variable), "its chunks hold 713 points, the header says 800");
  storeAt(variable, kLegacyCountAt, uint32_t{700});
  EXPECT_CONTAINS(lazError(variable), "its chunks hold more points than the header's 700");
  // A LAS 1.4 chunk holds its count after its first point (30 bytes of format 6).
  auto layered = test::readFile(sample("las14-f6-variable-evlr.laz"));
  const uint32_t firstChunk = loadAt<uint32_t>(layered, kPointDataOffsetAt) + 8;
  ASSERT_EQ(loadAt<uint32_t>(layered, firstChunk + 30), 150u);
  storeAt(layered, firstChunk + 30, uint32_t{999});
  EXPECT_CONTAINS(lazError(layered),
                  "chunk 1 of 6: the chunk says it holds 999 points, the "
                  "chunk table 150");
}

TEST_F(LazReader, damagedChunksAreFileErrorsNamingTheChunkOrDecodeToTheirCount) {
  // LAS 1.4 chunks: after the count, the sizes of their layers; huge ones make the decoder read
  // past its memory, which it refuses.
  auto layered = test::readFile(sample("las14-f6-variable-evlr.laz"));
  const uint32_t firstChunk = loadAt<uint32_t>(layered, kPointDataOffsetAt) + 8;
  std::fill_n(layered.begin() + firstChunk + 34, 12, std::byte{0xFF});
  const std::string error = lazError(layered);
  EXPECT_CONTAINS(error, "d.laz: byte " + std::to_string(firstChunk) +
                             ": chunk 1 of 6: the LAZ "
                             "decoder failed");
  // Anywhere else, damage decodes to other points or fails; never more, fewer or a crash.
  const auto good = test::readFile(sample("las12-f2-variable.laz"));
  const uint32_t data = loadAt<uint32_t>(good, kPointDataOffsetAt) + 8;
  const uint64_t table = chunkTableAt(good);
  for (uint64_t at = data; at < table; at += 241) {
    auto damaged = good;
    for (size_t i = 0; i < 16 && at + i < table; ++i) damaged[at + i] ^= std::byte(0x5A + i);
    test::TempDir dir;
    test::writeFile(dir / "d.laz", damaged);
    try {
      EXPECT_EQ(readPointFile(dir / "d.laz").size(), 713u);
    } catch (const FileError& e) {
      EXPECT_CONTAINS(std::string(e.what()), "d.laz: byte ");
    }
  }
}

TEST_F(LazReader, everyTruncatedPrefixIsAFileError) {
  const auto whole = test::readFile(sample("las10-f0-chunks100.laz"));
  test::TempDir dir;
  for (size_t length = 0; length < whole.size(); length += length < 2000 ? 1 : 7) {
    SCOPED_TRACE("prefix of " + std::to_string(length) + " bytes");
    test::writeFile(dir / "p.laz", {whole.begin(), whole.begin() + ptrdiff_t(length)});
    EXPECT_THROW(readPointFile(dir / "p.laz"), FileError);
  }
}

TEST_F(LazReader, aCompressedCopyOrANameWithoutTheSignatureIsRefusedSayingWhy) {
  test::TempDir dir;
  test::writeGzip(dir / "a.laz.gz", test::readFile(sample("las10-f0-chunks100.laz")));
  EXPECT_CONTAINS(test::readError(dir / "a.laz.gz"),
                  "a compressed copy of a LAZ file is not read: decompress it (gunzip) first");
  test::writeText(dir / "b.laz", "not a point file at all");
  EXPECT_CONTAINS(test::readError(dir / "b.laz"),
                  "b.laz: byte 0: not a LAZ file: no LASF signature");
}

TEST_F(LazReader, anUncompressedFileNamedLazIsReadAsLasWithANote) {
  test::TempDir dir;
  std::vector<std::byte> plain;
  {
    io::InputStream in(sample("las10-f0-chunks100.las.gz"));
    for (std::span<const std::byte> bytes = in.peek(1 << 16); !bytes.empty();
         bytes = in.peek(1 << 16)) {
      plain.insert(plain.end(), bytes.begin(), bytes.end());
      in.consume(bytes.size());
    }
  }
  test::writeFile(dir / "plain.laz", plain);
  const auto reader = openPointFile(dir / "plain.laz");
  EXPECT_EQ(reader->info().format, "las 1.0 format 0");
  EXPECT_EQ(reader->info().notes,
            std::vector<std::string>{"named .laz but its points are not compressed: read as LAS"});
  EXPECT_EQ(readPointFile(dir / "plain.laz").size(), 684u);
}

// The decoder itself: chunk by chunk against the LAS records, and a fresh start after a failure.
TEST_F(LazReader, aDecoderFailsCleanlyOnAChunkAndThenDecodesTheNextOne) {
  const std::filesystem::path path = sample("las14-f7-extrabytes.laz");
  io::InputStream in(path);
  const io::LasHeader header = io::readLasHeader(in);
  const auto bytes = test::readFile(path);
  const uint32_t chunkSize = io::checkLaszipRecord(
      in, header, std::span(bytes).subspan(laszipPayloadAt(bytes), 34 + 4 * 6));
  const std::vector<io::LazChunk> chunks =
      io::readLazChunkTable(in, header, chunkSize, bytes.size());
  ASSERT_EQ(chunks.size(), 4u);
  io::InputStream las(sample("las14-f7-extrabytes.las.gz"));
  const io::LasHeader lasHeader = io::readLasHeader(las);
  las.skip(lasHeader.pointDataOffset);
  io::LazChunkDecoder decoder;
  const size_t length = header.recordLength;
  for (const io::LazChunk& chunk : chunks) {
    const std::span<const std::byte> compressed(bytes.data() + chunk.offset, chunk.bytes);
    std::vector<std::byte> garbage(compressed.begin(), compressed.end());
    std::fill(garbage.begin() + ptrdiff_t(length + 4), garbage.end(), std::byte{0xEE});
    std::vector<std::byte> out(chunk.points * length);
    EXPECT_THROW(
        {
          decoder.open(header.pointFormat, length, garbage);
          decoder.decode(chunk.points, out.data());
        },
        io::LazDecodeError);
    decoder.open(header.pointFormat, length, compressed);
    decoder.decode(chunk.points, out.data());
    std::vector<std::byte> expected(out.size());
    ASSERT_TRUE(las.readExact(expected.data(), expected.size()));
    EXPECT_TRUE(out == expected);
  }
}

// A chunk that declares layers of hundreds of MiB (found by the point readers' fuzzer: 13 KiB of
// input took 1 GiB of the decoder's memory, and decoded) fails saying so, within a bounded memory.
TEST_F(LazReader, aChunkDeclaringHugeLayersFailsWithoutTakingTheirMemory) {
  const std::filesystem::path path = sample("las14-f6-variable-evlr.laz");
  io::InputStream in(path);
  const io::LasHeader header = io::readLasHeader(in);
  auto bytes = test::readFile(path);
  const uint32_t chunkSize = io::checkLaszipRecord(
      in, header, std::span(bytes).subspan(laszipPayloadAt(bytes), 34 + 4 * 9));
  const io::LazChunk chunk = io::readLazChunkTable(in, header, chunkSize, bytes.size()).at(0);
  // After the first point (30 bytes) and the count, the layers' sizes: the first four say 200 MiB.
  ASSERT_EQ(loadAt<uint32_t>(bytes, chunk.offset + 30), chunk.points);
  for (uint64_t layer = 0; layer < 4; ++layer)
    storeAt(bytes, chunk.offset + 34 + 4 * layer, uint32_t{200} << 20);
  io::LazChunkDecoder decoder;
  std::vector<std::byte> out(chunk.points * header.recordLength);
  try {
    decoder.open(header.pointFormat, header.recordLength,
                 std::span(bytes).subspan(chunk.offset, chunk.bytes));
    decoder.decode(chunk.points, out.data());
    ADD_FAILURE() << "decoded a chunk whose layers are larger than the chunk";
  } catch (const io::LazDecodeError& e) {
    EXPECT_CONTAINS(std::string(e.what()), "the sizes the chunk declares are damaged");
  }
  EXPECT_LT(decoder.memoryBytes(), size_t{32} << 20);
  EXPECT_CONTAINS(lazError(bytes), "chunk 1 of 6: the LAZ decoder failed");
}

}  // namespace
}  // namespace iso
