// LAZ and E57 inputs through `iso convert` and `iso eval` as a user gives them: the same surface
// from a LAZ file as from the LAS it decompresses to, directories of tiles mixed with other
// formats, the points' distances measured against LAZ and E57 inputs, and damaged files named,
// with nothing written.
#include <gtest/gtest.h>

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "iso/reader.h"
#include "pipeline/io/laz_decoder.h"
#include "pipeline/io/readers.h"
#include "tests/cli_support.h"

namespace iso {
namespace {

namespace fs = std::filesystem;
using test::quoted;
using test::runIso;

fs::path sample(const std::string& path) { return fs::path(ISO_TEST_DATA_DIR) / path; }

// The file's metadata without what names its inputs (paths and formats) and itself.
nlohmann::json surfaceMetadata(const Reader& reader) {
  nlohmann::json metadata = nlohmann::json::parse(reader.metadata());
  const auto drop = [](nlohmann::json& object, std::initializer_list<const char*> keys) {
    if (!object.is_object()) return;
    for (const char* key : keys) object.erase(key);
  };
  std::function<void(nlohmann::json&)> strip = [&](nlohmann::json& j) {
    drop(j, {"input", "inputs", "file", "format", "file_size"});
    if (j.is_object() || j.is_array())
      for (auto& child : j) strip(child);
  };
  strip(metadata);
  return metadata;
}

// Every chunk (table entry and stored bytes) of two files is the same, and their metadata but
// for the names of their inputs.
void expectSameSurface(const fs::path& a, const fs::path& b) {
  const Reader ra = Reader::open(a), rb = Reader::open(b);
  ASSERT_EQ(ra.chunks().size(), rb.chunks().size());
  for (size_t i = 0; i < ra.chunks().size(); ++i)
    EXPECT_TRUE(ra.chunks()[i] == rb.chunks()[i]) << "chunk " << i;
  EXPECT_EQ(surfaceMetadata(ra), surfaceMetadata(rb));
}

class CliInputs : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!io::hasLazDecoder()) GTEST_SKIP() << io::kLazDecoderMissing;
  }
  test::TempDir dir_;
};

TEST_F(CliInputs, aLazFileConvertsToTheSameSurfaceAsTheLasItDecompressesTo) {
  for (const char* name :
       {"las10-f0-chunks100", "las11-f1-geotiff", "las12-f2-variable", "las13-f3-onechunk",
        "las14-f6-variable-evlr", "las14-f7-extrabytes", "las14-f8-tableatend", "lion-tile-r006"}) {
    SCOPED_TRACE(name);
    for (const char* extension : {".laz", ".las.gz"}) {
      const auto run =
          runIso("convert -q " + quoted(sample(std::string("laz/") + name + extension)) + " -o " +
                 quoted(dir_ / (std::string(name) + extension + ".iso")));
      ASSERT_EQ(run.exitCode, 0) << run.err;
    }
    expectSameSurface(dir_ / (std::string(name) + ".laz.iso"),
                      dir_ / (std::string(name) + ".las.gz.iso"));
    const auto info = runIso("info --json " + quoted(dir_ / (std::string(name) + ".laz.iso")));
    const auto inputs = nlohmann::json::parse(info.out)["metadata"]["inputs"];
    ASSERT_EQ(inputs.size(), 1u);
    EXPECT_TRUE(inputs[0]["format"].get<std::string>().starts_with("laz 1."));
  }
}

TEST_F(CliInputs, theLionTilesAsPublishedConvertToTheSurfaceOfTheMergedLas) {
  const fs::path data(ISO_SHARED_DATA_DIR);
  if (!fs::is_directory(data / "lion_laz")) GTEST_SKIP() << "no shared data folder at " << data;
  const auto tiles = runIso("convert --progress none --json " + quoted(data / "lion_laz") + " -o " +
                            quoted(dir_ / "tiles.iso"));
  ASSERT_EQ(tiles.exitCode, 0) << tiles.err;
  EXPECT_EQ(nlohmann::json::parse(tiles.out)["points"]["input"], 341989);
  // One note for the 200 tiles' color coding, not 200.
  EXPECT_NE(tiles.err.find("note: 200 files ("), std::string::npos) << tiles.err;
  const auto las =
      runIso("convert -q " + quoted(data / "lion_rgb.las") + " -o " + quoted(dir_ / "las.iso"));
  ASSERT_EQ(las.exitCode, 0) << las.err;
  expectSameSurface(dir_ / "tiles.iso", dir_ / "las.iso");
}

TEST_F(CliInputs, aDirectoryMixesLazE57AndOtherFormats) {
  fs::create_directories(dir_ / "mixed");
  fs::copy(sample("laz/las12-f2-variable.laz"), dir_ / "mixed" / "a.laz");
  fs::copy(sample("laz/lion-tile-r006.laz"), dir_ / "mixed" / "b.laz");
  fs::copy(sample("e57/two-scans.e57"), dir_ / "mixed" / "c.e57");
  fs::copy(sample("laz/las10-f0-chunks100.las.gz"), dir_ / "mixed" / "d.las.gz");
  const auto run =
      runIso("convert -q --json " + quoted(dir_ / "mixed") + " -o " + quoted(dir_ / "mixed.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto report = nlohmann::json::parse(run.out);
  uint64_t expected = 0;
  for (const char* file : {"a.laz", "b.laz", "c.e57", "d.las.gz"}) {
    expected += readPointFile(dir_ / "mixed" / file).size();
    // The distances of each file's points to the surface, as a user checks a conversion.
    const auto eval =
        runIso("eval " + quoted(dir_ / "mixed.iso") + " --points " + quoted(dir_ / "mixed" / file));
    ASSERT_EQ(eval.exitCode, 0) << eval.err;
    const auto measured = nlohmann::json::parse(eval.out);
    EXPECT_GT(measured["points"].get<uint64_t>(), 0u) << file;
    EXPECT_LT(measured["rms_over_spacing"].get<double>(), 3.0) << file;
  }
  EXPECT_EQ(report["points"]["input"].get<uint64_t>(), expected);
  const auto info = nlohmann::json::parse(runIso("info --json " + quoted(dir_ / "mixed.iso")).out);
  std::vector<std::string> formats;
  for (const auto& input : info["metadata"]["inputs"]) formats.push_back(input["format"]);
  EXPECT_EQ(formats.size(), 4u);
  EXPECT_TRUE(formats[0].starts_with("laz 1.2"));
  EXPECT_TRUE(formats[2].starts_with("e57"));
  EXPECT_TRUE(formats[3].starts_with("las 1.0"));
}

TEST_F(CliInputs, damagedLazAndE57FilesAreNamedAndLeaveNoOutput) {
  const auto laz = test::readFile(sample("laz/las12-f2-variable.laz"));
  test::writeFile(dir_ / "cut.laz", {laz.begin(), laz.begin() + ptrdiff_t(laz.size() - 40)});
  const auto e57 = test::readFile(sample("e57/two-scans.e57"));
  auto flipped = e57;
  flipped[1500] ^= std::byte{0x20};
  test::writeFile(dir_ / "crc.e57", flipped);
  test::writeFile(dir_ / "old.iso", std::vector<std::byte>(10, std::byte{7}));
  for (const auto& [input, expected] : std::vector<std::pair<std::string, std::string>>{
           {"cut.laz", "damaged chunk table"}, {"crc.e57", "CRC"}}) {
    const auto run =
        runIso("convert -q -f " + quoted(dir_ / input) + " -o " + quoted(dir_ / "old.iso"));
    EXPECT_EQ(run.exitCode, 1) << input;
    EXPECT_NE(run.err.find((dir_ / input).string()), std::string::npos) << run.err;
    EXPECT_NE(run.err.find(expected), std::string::npos) << run.err;
    EXPECT_EQ(test::readFile(dir_ / "old.iso").size(), 10u) << "the old file was replaced";
  }
}

}  // namespace
}  // namespace iso
