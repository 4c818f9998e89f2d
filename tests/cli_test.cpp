// The `iso` program: info, verify, usage errors and exit codes, run as a user would run it.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>

#include "iso/writer.h"
#include "tests/cli_support.h"

namespace iso {
namespace {

const std::filesystem::path kGolden = std::filesystem::path(ISO_TEST_DATA_DIR) / "golden-v2.iso";

using test::CommandResult;
using test::quoted;

CommandResult iso(const std::string& arguments) { return test::runIso(arguments); }

TEST(Cli, verifyAcceptsTheGoldenFile) {
  const CommandResult run = iso("verify " + quoted(kGolden));
  EXPECT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("ok (6 chunks"), std::string::npos) << run.out;
}

TEST(Cli, verifyNamesTheChunkWhosePayloadByteFlipped) {
  test::TempDir dir;
  std::vector<std::byte> bytes = test::readFile(kGolden);
  bytes[8192 + 100] ^= std::byte{1};  // inside chunk 1's raw payload
  test::writeFile(dir / "flipped.iso", bytes);
  const CommandResult run = iso("verify " + quoted(dir / "flipped.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("chunk 1 (level 1, key 0x5) at byte 8192: checksum mismatch"),
            std::string::npos)
      << run.err;
  EXPECT_NE(run.err.find("FAILED (1 problem)"), std::string::npos) << run.err;

  const CommandResult json = iso("verify --json " + quoted(dir / "flipped.iso"));
  EXPECT_EQ(json.exitCode, 1);
  const nlohmann::json j = nlohmann::json::parse(json.out);
  EXPECT_EQ(j["ok"], false);
  EXPECT_EQ(j["problems"][0]["chunk"], 1);
}

TEST(Cli, verifyRejectsEveryTruncation) {
  test::TempDir dir;
  const std::vector<std::byte> bytes = test::readFile(kGolden);
  for (size_t size : {size_t{0}, size_t{100}, size_t{4096}, bytes.size() / 2, bytes.size() - 64,
                      bytes.size() - 1}) {
    test::writeFile(dir / "cut.iso", {bytes.begin(), bytes.begin() + ptrdiff_t(size)});
    const CommandResult run = iso("verify " + quoted(dir / "cut.iso"));
    EXPECT_EQ(run.exitCode, 1) << size;
    EXPECT_NE(run.err.find("cut.iso"), std::string::npos) << run.err;
  }
}

TEST(Cli, verifyRejectsMetadataThatIsNotJson) {
  test::TempDir dir;
  {
    Writer writer(dir / "meta.iso", FileHeader{});
    writer.setMetadata("{not json}");
    writer.finish();
  }
  const CommandResult run = iso("verify " + quoted(dir / "meta.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("metadata is not a JSON object"), std::string::npos) << run.err;
}

TEST(Cli, infoJsonIsValidAndComplete) {
  const CommandResult run = iso("info --json --chunks " + quoted(kGolden));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["format_version"], "2.2");
  EXPECT_EQ(j["chunk_count"], 6);
  EXPECT_EQ(j["frame"]["origin"][0].get<double>(), 515000.25);
  EXPECT_EQ(j["frame"]["origin"][2].get<double>(), -1234.125);
  EXPECT_EQ(j["frame"]["size"].get<double>(), 64.0);
  EXPECT_EQ(j["max_level"], 3);
  EXPECT_EQ(j["payload_alignment"], 4096);
  ASSERT_EQ(j["attributes"].size(), 3u);
  EXPECT_EQ(j["attributes"][0]["semantic"], "signed_distance");
  EXPECT_EQ(j["attributes"][0]["scale"].get<double>(), 0.5);
  EXPECT_EQ(j["attributes"][1]["encoding"], "oct16");
  EXPECT_EQ(j["attributes"][2]["semantic"], "color");
  EXPECT_EQ(j["point_count"], 1000);  // the root covers every point
  EXPECT_EQ(j["levels"][1]["points"], 600 + 40);
  EXPECT_EQ(j["raw_bytes"], 2000 + 300 + 1500 + 64 + 156);
  EXPECT_EQ(j["file_size"], std::filesystem::file_size(kGolden));
  EXPECT_EQ(j["metadata"]["generator"], "iso golden file v1");
  EXPECT_EQ(j["codecs"]["zstd"], 2);
  EXPECT_EQ(j["codecs"]["raw"], 4);
  ASSERT_EQ(j["chunks"].size(), 6u);
  EXPECT_TRUE(j["chunks"][0]["parent"].is_null());
  EXPECT_EQ(j["chunks"][2]["parent"], 1);
  EXPECT_EQ(j["chunks"][4]["kind"], "unknown");
  EXPECT_EQ(j["chunks"][5]["kind"], "surface");
  EXPECT_EQ(j["levels"].size(), 4u);
}

TEST(Cli, infoDoesNotWrapThePointCountsOfChunksItDoesNotKnow) {
  // Chunk 1 of the golden file is a blob (no rule on its point count) at level 1, beside chunk 5's
  // 40 points: the sum stops at 2^64 - 1 instead of wrapping to 39.
  test::TempDir dir;
  std::vector<std::byte> bytes = test::readFile(kGolden);
  uint64_t table = 0;
  std::memcpy(&table, bytes.data() + bytes.size() - 64, 8);
  const uint64_t most = ~uint64_t{0};
  std::memcpy(bytes.data() + table + 80 * 1 + 40, &most, 8);
  test::resealChecksums(bytes);
  test::writeFile(dir / "blob.iso", bytes);
  const CommandResult run = iso("info --json " + quoted(dir / "blob.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["levels"][1]["points"].get<uint64_t>(), most);
  EXPECT_EQ(j["point_count"], 1000);
}

TEST(Cli, infoForPeopleShowsTheEssentials) {
  const CommandResult run = iso("info " + quoted(kGolden));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("515000.25"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("signed_distance snorm8"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("iso golden file v1"), std::string::npos) << run.out;
}

TEST(Cli, badFilesAndUsageErrorsExitNonZeroWithAMessage) {
  CommandResult run = iso("info /no/such/file.iso");
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("/no/such/file.iso"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("No such file"), std::string::npos) << run.err;

  run = iso("info " + quoted(ISO_TEST_DATA_DIR));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("not a regular file"), std::string::npos) << run.err;

  run = iso("frobnicate");
  EXPECT_EQ(run.exitCode, 2);
  run = iso("info");
  EXPECT_EQ(run.exitCode, 2);
  EXPECT_NE(run.err.find("file is required"), std::string::npos) << run.err;
  run = iso("");
  EXPECT_EQ(run.exitCode, 2);
  run = iso("--help");
  EXPECT_EQ(run.exitCode, 0);
  EXPECT_NE(run.out.find("verify"), std::string::npos);
  run = iso("--version");
  EXPECT_EQ(run.exitCode, 0);
  EXPECT_NE(run.out.find(".iso format 2.2"), std::string::npos) << run.out;
}

}  // namespace
}  // namespace iso
