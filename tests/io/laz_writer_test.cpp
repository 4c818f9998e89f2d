// The benchmarks' LAZ writer (tests/support/laz_writer.h): its chunks are the bytes laz-perf's own
// compressor writes for the same points, and laz-perf decodes them to the LAS they came from.
#include <cstring>
#include <random>

#include "pipeline/io/input_stream.h"
#include "pipeline/io/las_records.h"
#include "pipeline/io/laz_chunks.h"
#include "pipeline/io/laz_decoder.h"
#include "tests/io/io_test_util.h"
#include "tests/io/las_file.h"
#include "tests/support/laz_writer.h"

namespace iso {
namespace {

constexpr size_t kPointDataOffsetAt = 96;

std::filesystem::path sample(const std::string& name) {
  return std::filesystem::path(ISO_TEST_DATA_DIR) / "laz" / name;
}

std::vector<std::byte> gunzip(const std::filesystem::path& path) {
  io::InputStream in(path);
  std::vector<std::byte> bytes;
  for (auto view = in.peek(1 << 16); !view.empty(); view = in.peek(1 << 16)) {
    bytes.insert(bytes.end(), view.begin(), view.end());
    in.consume(view.size());
  }
  return bytes;
}

// The bytes from the first chunk on (the header and VLRs name their writer).
std::vector<std::byte> chunks(const std::vector<std::byte>& laz) {
  uint32_t pointData = 0;
  std::memcpy(&pointData, laz.data() + kPointDataOffsetAt, 4);
  return {laz.begin() + pointData + 8, laz.end()};
}

// Every record of a LAZ file, decoded chunk by chunk.
std::vector<std::byte> decodeRecords(const std::filesystem::path& path) {
  io::InputStream in(path);
  const io::LasHeader header = io::readLasHeader(in);
  const auto bytes = test::readFile(path);
  std::vector<std::byte> laszip;
  std::vector<std::string> notes;
  io::readLasCoordinateSystem(in, header, header.pointDataOffset + 8, notes, &laszip);
  const uint32_t chunkSize = io::checkLaszipRecord(in, header, laszip);
  io::LazChunkDecoder decoder;
  std::vector<std::byte> records;
  for (const io::LazChunk& chunk : io::readLazChunkTable(in, header, chunkSize, bytes.size())) {
    const size_t at = records.size();
    records.resize(at + chunk.points * header.recordLength);
    decoder.open(header.pointFormat, header.recordLength,
                 std::span(bytes).subspan(chunk.offset, chunk.bytes));
    decoder.decode(chunk.points, records.data() + at);
  }
  return records;
}

class LazWriter : public testing::Test {
 protected:
  void SetUp() override {
    if (!io::hasLazDecoder()) GTEST_SKIP() << io::kLazDecoderMissing;
  }
  test::TempDir dir_;
};

TEST_F(LazWriter, writesTheChunksLazPerfsCompressorWrites) {
  test::writeFile(dir_ / "in.las", gunzip(sample("las10-f0-chunks100.las.gz")));
  bench::writeLazFromLas(dir_ / "in.las", dir_ / "out.laz", 100);
  const auto ours = test::readFile(dir_ / "out.laz");
  const auto theirs = test::readFile(sample("las10-f0-chunks100.laz"));
  EXPECT_EQ(ours.size(), theirs.size());
  EXPECT_TRUE(chunks(ours) == chunks(theirs));
  const ReadOptions keep{.columns = "", .keepExtras = true};
  const PointCloud expected = readPointFile(dir_ / "in.las", keep);
  const PointCloud decoded = readPointFile(dir_ / "out.laz", keep);
  EXPECT_TRUE(decoded.positions == expected.positions);
  EXPECT_TRUE(decoded.extras == expected.extras);
}

TEST_F(LazWriter, everyFieldOfPointFormatZeroRoundTripsThroughLazPerf) {
  // Random records: coordinates with jumps of every size, returns, flags, classes, scan angles,
  // user data and sources that change now and then, in chunks of 1,000 and a partial last one.
  std::mt19937 random(7);
  test::LasSpec spec{.minor = 2, .format = 0, .extraBytes = 0};
  const auto file = test::makeLas(spec);  // the header; records are appended below
  std::vector<std::byte> las = file.bytes();
  const size_t count = 4321;
  uint32_t x = 0, y = 0, z = 0;  // coordinates wrap around, as int32 records may
  for (size_t i = 0; i < count; ++i) {
    const uint32_t scale = 1u << (random() % 31);
    x += uint32_t(random() % 2001) - 1000 + (random() % 50 == 0 ? scale : 0);
    y += uint32_t(random() % 201) - 100;
    z = random() % 10 == 0 ? uint32_t(random()) : z + uint32_t(random() % 21) - 10;
    test::Bytes record;
    const uint8_t returns = uint8_t(1 + random() % 5);
    const uint8_t bits = uint8_t((1 + random() % returns) | (returns << 3) | (random() % 4) << 6);
    record.le(int32_t(x))
        .le(int32_t(y))
        .le(int32_t(z))
        .le(uint16_t(random() % 7 == 0 ? random() : 100));
    record.le(random() % 3 == 0 ? bits : uint8_t(0x09));
    record.le(uint8_t(random() % 5 == 0 ? random() % 32 : 2));
    record.le(int8_t(random() % 4 == 0 ? int(random() % 181) - 90 : 0));
    record.le(uint8_t(random() % 9 == 0 ? random() : 0))
        .le(uint16_t(random() % 11 == 0 ? random() : 7));
    las.insert(las.end(), record.bytes().begin(), record.bytes().end());
  }
  const uint32_t count32 = count;
  std::memcpy(las.data() + 107, &count32, 4);
  test::writeFile(dir_ / "r.las", las);
  bench::writeLazFromLas(dir_ / "r.las", dir_ / "r.laz", 1000);
  const ReadOptions keep{.columns = "", .keepExtras = true};
  const PointCloud expected = readPointFile(dir_ / "r.las", keep);
  ASSERT_EQ(expected.size(), count);
  const PointCloud decoded = readPointFile(dir_ / "r.laz", keep);
  EXPECT_TRUE(decoded.positions == expected.positions);
  EXPECT_TRUE(decoded.extras == expected.extras);
  // Every field, those points do not carry too: the decoded records are the LAS's.
  const std::vector<std::byte> records(las.begin() + 227, las.end());
  EXPECT_TRUE(decodeRecords(dir_ / "r.laz") == records);
}

TEST_F(LazWriter, refusesWhatItDoesNotWrite) {
  test::writeFile(dir_ / "c.las", gunzip(sample("las12-f2-variable.las.gz")));
  EXPECT_THROW(bench::writeLazFromLas(dir_ / "c.las", dir_ / "c.laz"), FileError);
}

}  // namespace
}  // namespace iso
