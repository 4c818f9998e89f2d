// `iso gen`, `iso convert` and `iso eval` run as a user would: outputs, reports, exit codes, and
// clear errors for bad input that leave nothing behind.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <sstream>
#include <vector>
#include <nlohmann/json.hpp>

#include <cstring>

#include <glm/geometric.hpp>

#include "iso/reader.h"
#include "iso/surface_model.h"
#include "pipeline/io/ply.h"
#include "pipeline/io/readers.h"
#include "tests/cli_support.h"
#include "tests/io/las_file.h"
#include "tests/pipeline/same_points.h"

namespace iso {
namespace {

using test::quoted;
using test::runIso;

class CliPipeline : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto run = runIso("gen sphere -n 20000 --seed 3 -o " + quoted(dir_ / "sphere.ply"));
    ASSERT_EQ(run.exitCode, 0) << run.err;
  }
  test::TempDir dir_;
};

TEST_F(CliPipeline, genConvertVerifyInfoAndEvalWorkTogether) {
  auto run =
      runIso("convert " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "sphere.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("bytes/leaf"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("accuracy"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("streamed: 1 chunk of at most"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("temporary disk"), std::string::npos) << run.out;
  EXPECT_NE(run.err.find("octree"), std::string::npos) << run.err;  // progress per stage
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "sphere.iso")).exitCode, 0);

  run = runIso("info --json " + quoted(dir_ / "sphere.iso"));
  ASSERT_EQ(run.exitCode, 0);
  const nlohmann::json info = nlohmann::json::parse(run.out);
  EXPECT_EQ(info["metadata"]["inputs"][0]["points"], 20000);
  EXPECT_EQ(info["metadata"]["parameters"]["leaf_points"], 8);
  EXPECT_GT(info["metadata"]["report"]["accuracy"]["samples"].get<int>(), 0);
  EXPECT_EQ(info["point_count"], 20000);

  run =
      runIso("eval " + quoted(dir_ / "sphere.iso") + " --shape sphere --rays 2000 --samples 5000");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json e = nlohmann::json::parse(run.out);
  for (const char* key : {"rms", "max", "spacing", "rms_over_spacing", "max_over_spacing",
                          "normal_median_deg", "normal_p99_deg", "hole_rate"})
    EXPECT_TRUE(e.contains(key)) << key;
  EXPECT_LT(e["rms_over_spacing"].get<double>(), 0.2);
  EXPECT_EQ(e["holes"], 0);

  run = runIso("eval " + quoted(dir_ / "sphere.iso") + " --points " + quoted(dir_ / "sphere.ply"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out)["points"], 20000);
}

TEST_F(CliPipeline, convertWritesTheSameBytesOnAnyNumberOfThreads) {
  // Without input normals, so that estimation and orientation run too.
  const auto gen = runIso("gen torus -n 30000 --seed 5 --no-normals -o " + quoted(dir_ / "t.ply"));
  ASSERT_EQ(gen.exitCode, 0);
  std::string bytes[3];
  for (int threads : {1, 2, 0}) {
    const auto out = dir_ / ("t" + std::to_string(threads) + ".iso");
    // Small orientation blocks, so that components are aligned across blocks too.
    const auto run = runIso("convert -q --orient-block-points 512 --memory 4M --threads " +
                            std::to_string(threads) + " " + quoted(dir_ / "t.ply") + " -o " +
                            quoted(out));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    bytes[threads] = test::slurp(out);
  }
  EXPECT_GT(bytes[1].size(), 1000u);
  EXPECT_TRUE(bytes[1] == bytes[2]) << "1 thread and 2 threads differ";
  EXPECT_TRUE(bytes[1] == bytes[0]) << "1 thread and all cores differ";
}

TEST_F(CliPipeline, aTinyMemoryBudgetGivesTheSameFileAsAHugeOne) {
  const auto gen =
      runIso("gen torus -n 60000 --noise 0.3 --no-normals -o " + quoted(dir_ / "t.ply"));
  ASSERT_EQ(gen.exitCode, 0);
  std::string bytes[2];
  nlohmann::json reports[2];
  const char* budgets[2] = {"150K", "8G"};
  for (int b = 0; b < 2; ++b) {
    const auto out = dir_ / ("t" + std::to_string(b) + ".iso");
    const auto run = runIso(std::string("convert -q --json --orient-block-points 256 --memory ") +
                            budgets[b] + " --tmp " + quoted(dir_.path()) + " " +
                            quoted(dir_ / "t.ply") + " -o " + quoted(out));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    reports[b] = nlohmann::json::parse(run.out);
    bytes[b] = test::slurp(out);
  }
  EXPECT_GE(reports[0]["out_of_core"]["chunks"].get<int>(), 150);
  EXPECT_EQ(reports[1]["out_of_core"]["chunks"].get<int>(), 1);
  EXPECT_GT(reports[0]["out_of_core"]["temporary_bytes_peak"].get<uint64_t>(), 60000u * 24);
  EXPECT_TRUE(bytes[0] == bytes[1]) << "the budget changed the output";
  for (const auto& entry : std::filesystem::directory_iterator(dir_.path()))
    EXPECT_NE(entry.path().extension(), ".isotmp") << "left behind: " << entry.path();
}

TEST_F(CliPipeline, aTemporaryDiskLimitIsKeptOrTheConversionStopsWithNothingWritten) {
  ASSERT_EQ(runIso("gen torus -n 100000 --noise 0.3 -o " + quoted(dir_ / "t.ply")).exitCode, 0);
  const std::string convert = "convert -q --json --memory 150K --tmp " + quoted(dir_.path()) + " " +
                              quoted(dir_ / "t.ply") + " -o " + quoted(dir_ / "t.iso");
  auto run = runIso(convert + " --max-temp 1G");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json c = nlohmann::json::parse(run.out)["out_of_core"];
  const uint64_t peak = c["temporary_disk_peak"].get<uint64_t>();
  EXPECT_EQ(c["temporary_disk_limit"].get<uint64_t>(), uint64_t{1} << 30);
  // The points' files and the spilled arrays together: at least each of them at its own peak.
  EXPECT_GE(peak, c["temporary_bytes_peak"].get<uint64_t>());
  EXPECT_GT(peak, c["spilled_bytes_peak"].get<uint64_t>());
  EXPECT_LE(peak, uint64_t{1} << 30);
  // Half of that: the conversion stops with an error naming the limit, the old output stays.
  std::ofstream(dir_ / "t.iso", std::ios::trunc) << "old";
  run = runIso(convert + " -f --max-temp " + std::to_string(peak / 2));
  EXPECT_EQ(run.exitCode, 1) << run.err;
  EXPECT_NE(run.err.find("the temporary files would exceed --max-temp"), std::string::npos)
      << run.err;
  EXPECT_EQ(test::slurp(dir_ / "t.iso"), "old");
  for (const auto& entry : std::filesystem::directory_iterator(dir_.path()))
    EXPECT_NE(entry.path().extension(), ".isotmp") << "left behind: " << entry.path();
  run = runIso(convert + " -f --max-temp lots");
  EXPECT_EQ(run.exitCode, 2) << run.err;
  EXPECT_NE(run.err.find("--max-temp"), std::string::npos) << run.err;
}

TEST_F(CliPipeline, badMemoryAndTemporaryDirectoriesAreRefused) {
  for (const char* options : {"--memory lots", "--memory -2G", "--memory 0"}) {
    const auto run = runIso(std::string("convert ") + options + " " + quoted(dir_ / "sphere.ply") +
                            " -o " + quoted(dir_ / "x.iso"));
    EXPECT_EQ(run.exitCode, 2) << options << run.err;
    EXPECT_NE(run.err.find("--memory"), std::string::npos) << run.err;
  }
  const auto run = runIso("convert --tmp " + quoted(dir_ / "missing") + " " +
                          quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "x.iso"));
  EXPECT_EQ(run.exitCode, 1) << run.err;
  EXPECT_NE(run.err.find("missing"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.iso"));
}

TEST_F(CliPipeline, convertReportsProgressAsJsonAndWritesTheReportFile) {
  const auto run = runIso("convert --progress json --report " + quoted(dir_ / "r.json") + " " +
                          quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  std::istringstream lines(run.err);
  std::string line;
  std::vector<std::string> ended;
  while (std::getline(lines, line)) {
    const nlohmann::json j = nlohmann::json::parse(line);  // every line is one object
    for (const char* key : {"stage", "done", "elapsed_seconds", "per_second", "rss_bytes"})
      EXPECT_TRUE(j.contains(key)) << line;
    EXPECT_GT(j["rss_bytes"].get<uint64_t>(), 0u);
    if (j["event"] == "end") ended.push_back(j["stage"]);
    if (j.contains("percent")) {
      EXPECT_LE(j["percent"].get<double>(), 100.0);
    }
    if (j.contains("total")) {
      EXPECT_LE(j["done"].get<uint64_t>(), j["total"].get<uint64_t>()) << line;
    }
  }
  const std::vector<std::string> stages = {"read",   "distribute",      "points",  "orient",
                                           "octree", "passive+balance", "corners", "lod",
                                           "write",  "accuracy",        "visibility"};
  EXPECT_EQ(ended, stages);
  const nlohmann::json report = nlohmann::json::parse(test::slurp(dir_ / "r.json"));
  EXPECT_EQ(report["points"]["input"], 20000);
  EXPECT_GT(report["peak_rss_bytes"].get<uint64_t>(), 0u);
  ASSERT_EQ(report["stages"].size(), stages.size());
  // The file keeps the report without what varies from run to run.
  const auto info = runIso("info --json " + quoted(dir_ / "s.iso"));
  const nlohmann::json stored = nlohmann::json::parse(info.out)["metadata"]["report"];
  EXPECT_FALSE(stored.contains("stages"));
  EXPECT_FALSE(stored.contains("peak_rss_bytes"));
  EXPECT_EQ(stored["accuracy"], report["accuracy"]);
  // What the viewer shows of the scan: a closed sphere, every point seen, none seen through.
  EXPECT_EQ(stored["visibility"], report["visibility"]);
  EXPECT_EQ(report["visibility"]["points"].get<uint64_t>(), 20000u);
  EXPECT_EQ(report["visibility"]["views"].get<uint64_t>(), 8u);
  EXPECT_EQ(report["visibility"]["seen_through"].get<uint64_t>(), 0u);
  EXPECT_LT(report["visibility"]["depth_error_median"].get<double>(), 0.5);
}

TEST_F(CliPipeline, convertBakesATextureAndAmbientOcclusion) {
  // A 2 × 2 binary PPM texture.
  const std::string header = "P6\n2 2\n255\n";
  const uint8_t texels[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
  std::vector<std::byte> bytes(header.size() + sizeof texels);
  std::memcpy(bytes.data(), header.data(), header.size());
  std::memcpy(bytes.data() + header.size(), texels, sizeof texels);
  test::writeFile(dir_ / "tex.ppm", bytes);
  const auto run = runIso("convert " + quoted(dir_ / "sphere.ply") + " -o " +
                          quoted(dir_ / "t.iso") + " --texture " + quoted(dir_ / "tex.ppm") +
                          " --texture-scale 0.5 --bake-ao --ao-rays 8");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("texture: tex.ppm (2×2) sampled at the corners"), std::string::npos)
      << run.out;
  EXPECT_NE(run.out.find("ambient occlusion:"), std::string::npos) << run.out;
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "t.iso")).exitCode, 0);
  const auto info = runIso("info --json " + quoted(dir_ / "t.iso"));
  ASSERT_EQ(info.exitCode, 0) << info.err;
  EXPECT_NE(info.out.find("\"occlusion\""), std::string::npos);
  EXPECT_NE(info.out.find("\"color\""), std::string::npos);
}

TEST_F(CliPipeline, badTexturesAndImpossibleBakeOptionsLeaveTheOldFile) {
  const std::vector<std::byte> old(64, std::byte{7});
  test::writeFile(dir_ / "out.iso", old);
  test::writeFile(dir_ / "notes.png", std::vector<std::byte>(32, std::byte{'a'}));
  const std::string convert =
      "convert -f " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "out.iso");
  for (const char* image : {"missing.png", "notes.png"}) {
    const auto run = runIso(convert + " --texture " + quoted(dir_ / image));
    EXPECT_EQ(run.exitCode, 1) << image;
    EXPECT_NE(run.err.find(image), std::string::npos) << run.err;
  }
  for (const char* options :
       {"--texture-scale 2", "--ao-rays 8", "--ao-radius 1", "--bake-ao --ao-rays 0",
        "--bake-ao --ao-radius -1", "--texture-at sideways --texture x.png",
        "--texture-sharpness -1 --texture x.png"}) {
    const auto run = runIso(convert + " " + options);
    EXPECT_EQ(run.exitCode, 2) << options << "\n" << run.err;
  }
  EXPECT_TRUE(test::readFile(dir_ / "out.iso") == old);
}

TEST_F(CliPipeline, exportWritesAMeshOfTheSurfaceAndRefusesToClobber) {
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const std::string out = quoted(dir_ / "s-mesh.ply");
  auto run = runIso("export --json " + quoted(dir_ / "s.iso") + " --mesh " + out);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json summary = nlohmann::json::parse(run.out)["mesh"];
  const TriangleMesh mesh = readPlyMesh(dir_ / "s-mesh.ply");
  EXPECT_EQ(summary["triangles"].get<size_t>(), mesh.triangles.size());
  EXPECT_EQ(summary["vertices"].get<size_t>(), mesh.vertices.size());
  EXPECT_GT(mesh.triangles.size(), 10000u);
  for (const glm::dvec3& v : mesh.vertices) ASSERT_NEAR(glm::length(v), 1.0, 0.02);
  // Not over an existing file without --force; with it, the same bytes again.
  const std::vector<std::byte> first = test::readFile(dir_ / "s-mesh.ply");
  run = runIso("export " + quoted(dir_ / "s.iso") + " --mesh " + out);
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("s-mesh.ply"), std::string::npos) << run.err;
  run = runIso("export -f " + quoted(dir_ / "s.iso") + " --mesh " + out);
  EXPECT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("triangles"), std::string::npos);
  EXPECT_TRUE(test::readFile(dir_ / "s-mesh.ply") == first);
  // A level set that OpenVDB's own vdb_print reads.
  run = runIso("export " + quoted(dir_ / "s.iso") + " --vdb " + quoted(dir_ / "s.vdb"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("active voxels"), std::string::npos) << run.out;
  EXPECT_EQ(std::system(("vdb_print " + quoted(dir_ / "s.vdb") + " > /dev/null").c_str()), 0);
  EXPECT_EQ(runIso("export " + quoted(dir_ / "s.iso") + " --vdb " + quoted(dir_ / "t.vdb") +
                   " --band 0.5")
                .exitCode,
            2);
  // No output asked for: a usage error. A file that is not an .iso file: its name, no output.
  EXPECT_EQ(runIso("export " + quoted(dir_ / "s.iso")).exitCode, 2);
  run = runIso("export " + quoted(dir_ / "sphere.ply") + " --mesh " + quoted(dir_ / "x.ply"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("sphere.ply"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.ply"));
}

TEST_F(CliPipeline, keptPointsExportAsTheInputPointsAndBrokenOnesAreReported) {
  // Real scans with normals (the kitten) and colors (the lion, 8-bit codes times 256, when
  // ../shared/data is there), and a sphere 5,000 km from the origin: every point back within the
  // precision asked for, one to one.
  const auto gen = runIso("gen sphere -n 20000 --seed 4 --offset 500000,4900000,1200 -o " +
                          quoted(dir_ / "far.ply"));
  ASSERT_EQ(gen.exitCode, 0) << gen.err;
  // The kitten again with 8-bit colors, as an ASCII PLY: colors come back exactly.
  const std::filesystem::path kitten =
      std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz";
  PointCloud colored = readPointFile(kitten);
  for (size_t i = 0; i < colored.size(); ++i)
    colored.colors.push_back(glm::vec3(srgb8ToLinear(uint8_t(i * 7)), srgb8ToLinear(uint8_t(i)),
                                       srgb8ToLinear(uint8_t(255 - i % 256))));
  writePly(dir_ / "colored.ply", colored, {.binary = false});
  struct Case {
    std::filesystem::path input;
    int bits, colorCodes;
  };
  std::vector<Case> cases = {
      {kitten, 24, 0}, {dir_ / "colored.ply", 16, 0}, {dir_ / "far.ply", 30, 0}};
  const std::filesystem::path lion = std::filesystem::path(ISO_SHARED_DATA_DIR) / "lion_rgb.las";
  if (std::filesystem::exists(lion)) cases.push_back({lion, 20, 0});  // read as 8-bit codes
  for (const Case& c : cases) {
    SCOPED_TRACE(c.input.string());
    const std::string iso = quoted(dir_ / "k.iso"), ply = quoted(dir_ / "k.ply");
    auto run = runIso("convert -q -f --json --keep-points --point-bits " + std::to_string(c.bits) +
                      " " + quoted(c.input) + " -o " + iso);
    ASSERT_EQ(run.exitCode, 0) << run.err;
    const nlohmann::json report = nlohmann::json::parse(run.out);
    const PointCloud input = readPointFile(c.input);
    EXPECT_EQ(report["kept_points"]["points"], input.size());
    EXPECT_EQ(report["kept_points"]["coarser_chunks"], 0);
    ASSERT_EQ(runIso("verify " + iso).exitCode, 0);
    run = runIso("info --json " + iso);
    const nlohmann::json info = nlohmann::json::parse(run.out);
    EXPECT_EQ(info["kept_points"]["points"], input.size());
    EXPECT_EQ(info["point_count"], report["points"]["used"].get<uint64_t>() +
                                       report["points"]["duplicates_merged"].get<uint64_t>());
    run = runIso("export -f --json " + iso + " --points " + ply);
    ASSERT_EQ(run.exitCode, 0) << run.err;
    EXPECT_EQ(nlohmann::json::parse(run.out)["points"]["points"], input.size());
    const double step = std::ldexp(info["frame"]["size"].get<double>(), -c.bits);
    EXPECT_LE(report["kept_points"]["max_error"].get<double>(), std::sqrt(3.0) / 2.0 * step * 1.01);
    test::expectSamePoints(input, readPointFile(dir_ / "k.ply"), std::sqrt(3.0) / 2.0 * step * 1.01,
                           c.colorCodes);
  }

  // A file without kept points; options that make no sense; the old output stays.
  const std::string plain = quoted(dir_ / "plain.iso");
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + plain).exitCode, 0);
  auto run = runIso("export " + plain + " --points " + quoted(dir_ / "x.ply"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("plain.iso"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("keeps no points"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.ply"));
  const std::vector<std::byte> old = test::readFile(dir_ / "plain.iso");
  for (const std::string options :
       {"--keep-points --point-bits 31", "--keep-points --point-bits 7", "--point-bits 20"}) {
    run = runIso("convert -q -f " + options + " " + quoted(dir_ / "sphere.ply") + " -o " + plain);
    EXPECT_EQ(run.exitCode, 2) << options << "\n" << run.err;
  }
  EXPECT_TRUE(test::readFile(dir_ / "plain.iso") == old);

  // One bit flipped in a points chunk: verify names the chunk, export writes nothing.
  run = runIso("info --json --chunks " + quoted(dir_ / "k.iso"));
  const nlohmann::json chunks = nlohmann::json::parse(run.out)["chunks"];
  uint64_t at = 0, id = 0;
  for (const nlohmann::json& chunk : chunks)
    if (chunk["kind"] == "points") {
      at = chunk["offset"].get<uint64_t>() + chunk["stored_bytes"].get<uint64_t>() / 2;
      id = chunk["id"].get<uint64_t>();
    }
  ASSERT_GT(at, 0u);
  std::vector<std::byte> bytes = test::readFile(dir_ / "k.iso");
  bytes[at] ^= std::byte{0x10};
  test::writeFile(dir_ / "broken.iso", bytes);
  run = runIso("verify " + quoted(dir_ / "broken.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE((run.out + run.err).find("chunk " + std::to_string(id)), std::string::npos)
      << run.out << run.err;
  run = runIso("export " + quoted(dir_ / "broken.iso") + " --points " + quoted(dir_ / "b.ply"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("broken.iso"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("checksum"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "b.ply"));
}

TEST_F(CliPipeline, evalComparesTwoFilesAndEveryLevelOfDetail) {
  const std::string iso = quoted(dir_ / "s.iso"), ply = quoted(dir_ / "sphere.ply");
  ASSERT_EQ(runIso("convert -q " + ply + " -o " + iso).exitCode, 0);
  ASSERT_EQ(runIso("convert -q --max-depth 5 " + ply + " -o " + quoted(dir_ / "c.iso")).exitCode,
            0);
  auto run = runIso("eval " + iso + " --against " + quoted(dir_ / "c.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json e = nlohmann::json::parse(run.out);
  EXPECT_GT(e["rms_over_spacing"].get<double>(), 0.0);
  EXPECT_GT(e["a_to_b"]["samples"].get<uint64_t>(), 1000u);
  run = runIso("eval " + iso + " --points " + ply + " --per-level");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json levels = nlohmann::json::parse(run.out)["levels"];
  ASSERT_GE(levels.size(), 3u);
  EXPECT_LT(levels.back()["rms"].get<double>(), levels[1]["rms"].get<double>());
  // --per-level needs --points; one truth at a time.
  EXPECT_EQ(runIso("eval " + iso + " --shape sphere --per-level").exitCode, 2);
  EXPECT_EQ(runIso("eval " + iso + " --points " + ply + " --against " + iso).exitCode, 2);
  run = runIso("eval " + iso + " --against " + quoted(dir_ / "missing.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("missing.iso"), std::string::npos) << run.err;
}

TEST_F(CliPipeline, evalMeasuresWhatTheViewerShowsAndWritesThePointsSeenThrough) {
  const std::string iso = quoted(dir_ / "s.iso"), ply = quoted(dir_ / "sphere.ply");
  ASSERT_EQ(runIso("convert -q --keep-points " + ply + " -o " + iso).exitCode, 0);
  // The input points: a closed sphere shows all of them from every view.
  auto run = runIso("eval " + iso + " --visibility --points " + ply + " --views 2");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  nlohmann::json v = nlohmann::json::parse(run.out)["visibility"];
  EXPECT_EQ(v["points"], 20000);
  EXPECT_EQ(v["views"], 8);
  EXPECT_EQ(v["per_view"].size(), 8u);
  EXPECT_EQ(v["seen_through"], 0);
  EXPECT_LT(v["depth_error_median"].get<double>(), 0.3);
  // Without --points: the file's kept points, every second one.
  run = runIso("eval " + iso + " --visibility --visibility-points 10000");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out)["visibility"]["points"], 10000);
  // Points of a cube around the sphere, inside the frame: those outside the sphere's outline in a
  // view are seen through (a line through a point inside the sphere always meets it), and
  // written out.
  ASSERT_EQ(runIso("gen cube -n 4000 --half-size 0.99 --seed 5 -o " + quoted(dir_ / "cube.ply"))
                .exitCode,
            0);
  run = runIso("eval " + iso + " --visibility --points " + quoted(dir_ / "cube.ply") +
               " --seen-through " + quoted(dir_ / "seen.ply"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  v = nlohmann::json::parse(run.out)["visibility"];
  EXPECT_GT(v["seen_through"].get<uint64_t>(), 1000u);
  const PointCloud seen = readPointFile(dir_ / "seen.ply");
  EXPECT_GT(seen.size(), 100u);
  for (const glm::dvec3& p : seen.positions) EXPECT_GT(glm::length(p), 1.0);
  // The file is not replaced without --force; --seen-through needs --visibility; a file without
  // kept points needs --points.
  run = runIso("eval " + iso + " --visibility --points " + quoted(dir_ / "cube.ply") +
               " --seen-through " + quoted(dir_ / "seen.ply"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("seen.ply"), std::string::npos) << run.err;
  EXPECT_EQ(runIso("eval " + iso + " --points " + ply + " --seen-through " +
                   quoted(dir_ / "other.ply"))
                .exitCode,
            2);
  ASSERT_EQ(runIso("convert -q " + ply + " -o " + quoted(dir_ / "plain.iso")).exitCode, 0);
  run = runIso("eval " + quoted(dir_ / "plain.iso") + " --visibility");
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("keeps no points"), std::string::npos) << run.err;
  EXPECT_EQ(runIso("eval " + iso + " --visibility --pixel 0 --points " + ply).exitCode, 2);
}

TEST_F(CliPipeline, convertRefusesImpossibleThreadAndProgressOptions) {
  for (const char* options : {"--threads -1", "--progress sometimes"}) {
    const auto run = runIso(std::string("convert ") + options + " " + quoted(dir_ / "sphere.ply") +
                            " -o " + quoted(dir_ / "x.iso"));
    EXPECT_EQ(run.exitCode, 2) << options << run.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / "x.iso"));
  }
}

// Start `iso convert` and deliver `signal` as soon as its temporary output file exists; returns
// the temporary file's name, empty if the run ended before one appeared.
std::string interruptWhileWriting(const std::filesystem::path& input,
                                  const std::filesystem::path& output, int signal) {
  const std::string binary = ISO_BINARY;
  std::vector<std::string> args = {binary, "convert", "-q", "-f", input.string(), "-o",
                                   output.string()};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t child = 0;
  if (posix_spawn(&child, binary.c_str(), nullptr, nullptr, argv.data(), environ) != 0) return "";
  std::string temporary;
  for (int status = 0; temporary.empty();) {
    const std::string prefix =
        "." + output.filename().string() + "." + std::to_string(child) + "-";
    for (const auto& entry : std::filesystem::directory_iterator(output.parent_path()))
      if (entry.path().filename().string().starts_with(prefix))
        temporary = entry.path().filename().string();
    if (!temporary.empty()) break;
    if (waitpid(child, &status, WNOHANG) == child) return "";  // finished first
    usleep(200);
  }
  kill(child, signal);
  int status = 0;
  waitpid(child, &status, 0);
  return temporary;
}

TEST_F(CliPipeline, anInterruptedConversionLeavesTheOldFileAndNoTemporaryFiles) {
  ASSERT_EQ(runIso("gen torus -n 300000 -o " + quoted(dir_ / "big.ply")).exitCode, 0);
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "out.iso"))
                .exitCode,
            0);
  const std::string old = test::slurp(dir_ / "out.iso");
  const auto temporaries = [&] {
    size_t n = 0;
    for (const auto& entry : std::filesystem::directory_iterator(dir_.path()))
      n += entry.path().extension() == ".isotmp";
    return n;
  };

  // Ctrl-C: the handler removes the temporary file.
  std::string temporary = interruptWhileWriting(dir_ / "big.ply", dir_ / "out.iso", SIGINT);
  ASSERT_FALSE(temporary.empty()) << "the conversion ended before it could be interrupted";
  EXPECT_EQ(temporaries(), 0u);
  EXPECT_TRUE(test::slurp(dir_ / "out.iso") == old);

  // kill -9: nothing can clean up, but the old file is intact and the next run removes the
  // temporary file.
  temporary = interruptWhileWriting(dir_ / "big.ply", dir_ / "out.iso", SIGKILL);
  ASSERT_FALSE(temporary.empty());
  EXPECT_EQ(temporaries(), 2u);  // the output's and the directory of spilled points
  EXPECT_TRUE(test::slurp(dir_ / "out.iso") == old);
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "out.iso")).exitCode, 0);
  const auto run = runIso("convert -f " + quoted(dir_ / "sphere.ply") + " -o " +
                          quoted(dir_ / "again.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.err.find("removed 2 temporary files"), std::string::npos) << run.err;
  EXPECT_EQ(temporaries(), 0u);
}

TEST_F(CliPipeline, convertRefusesToReplaceAnExistingFileWithoutForce) {
  test::writeFile(dir_ / "out.iso", {std::byte{'o'}, std::byte{'l'}, std::byte{'d'}});
  auto run =
      runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "out.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("exists already"), std::string::npos) << run.err;
  EXPECT_EQ(test::slurp(dir_ / "out.iso"), "old");
  run = runIso("convert -q --force " + quoted(dir_ / "sphere.ply") + " -o " +
               quoted(dir_ / "out.iso"));
  EXPECT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "out.iso")).exitCode, 0);
}

TEST_F(CliPipeline, badInputIsNamedAndLeavesNoOutput) {
  // A missing file, a truncated PLY, an empty PLY, a LAZ file.
  const std::vector<std::byte> ply = test::readFile(dir_ / "sphere.ply");
  test::writeFile(dir_ / "cut.ply", {ply.begin(), ply.begin() + ptrdiff_t(ply.size() / 2)});
  std::ofstream(dir_ / "empty.ply")
      << "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n";
  test::writeFile(dir_ / "scan.laz", std::vector<std::byte>(400, std::byte{0}));
  // Inputs that define no surface: one point, one point repeated, two points, a line.
  std::ofstream(dir_ / "one.xyz") << "1 2 3\n";
  std::ofstream(dir_ / "same.xyz") << "1 2 3\n1 2 3\n1 2 3\n1 2 3\n";
  std::ofstream(dir_ / "two.xyz") << "1 2 3\n4 5 6\n";
  std::ofstream(dir_ / "line.xyz") << "0 0 0\n1 1 1\n2 2 2\n3 3 3\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"missing.ply", "missing.ply"}, {"cut.ply", "file ends after"},
      {"empty.ply", "no points"},     {"scan.laz", "LAZ"},
      {"one.xyz", "at least 3 distinct points"}, {"same.xyz", "the input has 1"},
      {"two.xyz", "the input has 2"}, {"line.xyz", "one line"}};
  for (const auto& [input, expected] : cases) {
    const auto run =
        runIso("convert -q " + quoted(dir_ / input) + " -o " + quoted(dir_ / "bad.iso"));
    EXPECT_EQ(run.exitCode, 1) << input;
    EXPECT_NE(run.err.find(input), std::string::npos) << run.err;
    EXPECT_NE(run.err.find(expected), std::string::npos) << run.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / "bad.iso")) << input;
  }
  for (const auto& entry : std::filesystem::directory_iterator(dir_.path()))
    EXPECT_EQ(entry.path().extension() == ".isotmp", false) << entry.path();
}

TEST_F(CliPipeline, aFullDiskIsAClearErrorThatLeavesNothingBehind) {
  // A 1 MiB file system for the temporary files, then for the output (needs mount: as root).
  const auto small = dir_ / "small";
  std::filesystem::create_directory(small);
  if (std::system(("mount -t tmpfs -o size=1m tmpfs " + quoted(small) + " 2>/dev/null").c_str()) !=
      0)
    GTEST_SKIP() << "cannot mount a small file system here (not root)";
  struct Unmount {
    std::string path;
    ~Unmount() { (void)std::system(("umount " + path).c_str()); }
  } unmount{quoted(small)};
  ASSERT_EQ(runIso("gen torus -n 100000 -o " + quoted(dir_ / "t.ply")).exitCode, 0);
  // (--max-temp auto would stop it first, at 90 % of the free space: the disk itself is tested.)
  auto run = runIso("convert -q --max-temp 1G " + quoted(dir_ / "t.ply") + " -o " +
                    quoted(dir_ / "t.iso") + " --tmp " + quoted(small));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("No space left on device"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("temporary file"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "t.iso"));
  EXPECT_TRUE(std::filesystem::is_empty(small));
  // By default it stops at 90 % of the free space, before the disk is full.
  run = runIso("convert -q " + quoted(dir_ / "t.ply") + " -o " + quoted(dir_ / "t.iso") +
               " --tmp " + quoted(small));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("would exceed --max-temp 9"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "t.iso"));
  EXPECT_TRUE(std::filesystem::is_empty(small));
  // The output on a full file system: an old file there stays as it was.
  std::ofstream(small / "t.iso") << "old";
  std::ofstream(small / "filler") << std::string((1u << 20) - (16u << 10), 'x');
  run = runIso("convert -q -f " + quoted(dir_ / "t.ply") + " -o " + quoted(small / "t.iso") +
               " --tmp " + quoted(dir_.path()));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("No space left on device"), std::string::npos) << run.err;
  EXPECT_EQ(test::slurp(small / "t.iso"), "old");
  size_t entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(small)) entries += entry.exists();
  EXPECT_EQ(entries, 2u);  // the old file and the filler, nothing else
}

TEST_F(CliPipeline, nonFinitePointsAreDroppedAndCounted) {
  std::ofstream(dir_ / "nan.xyz")
      << "0 0 0\n1 0 0\nnan 1 0\n0 1 0\ninf 0 0\n1 1 0.01\n0.5 0.5 0.02\n0.2 0.7 0\n";
  const auto run =
      runIso("convert -q --json " + quoted(dir_ / "nan.xyz") + " -o " + quoted(dir_ / "nan.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json report = nlohmann::json::parse(run.out);
  EXPECT_EQ(report["points"]["non_finite_dropped"], 2);
  EXPECT_EQ(report["points"]["input"], 8);
}

TEST_F(CliPipeline, impossibleOptionsAreUsageErrors) {
  for (const std::string options :
       {"--max-depth 30", "--leaf-points 0", "--normal-bits 10", "--fit cubic", "--orient sideways",
        "--smoothing -1", "--tolerance nan"}) {
    const auto run = runIso("convert -q " + options + " " + quoted(dir_ / "sphere.ply") + " -o " +
                            quoted(dir_ / "x.iso"));
    EXPECT_EQ(run.exitCode, 2) << options << ": " << run.err;
    EXPECT_FALSE(run.err.empty());
    EXPECT_FALSE(std::filesystem::exists(dir_ / "x.iso"));
  }
  EXPECT_EQ(runIso("gen -o " + quoted(dir_ / "x.ply")).exitCode, 2);  // no shape
  EXPECT_EQ(runIso("gen torus --minor-radius 2 -o " + quoted(dir_ / "x.ply")).exitCode, 2);
  EXPECT_EQ(runIso("gen sphere --offset 1,2 -o " + quoted(dir_ / "x.ply")).exitCode, 2);
  EXPECT_EQ(runIso("eval " + quoted(dir_ / "sphere.ply")).exitCode, 2);  // no truth
}

TEST_F(CliPipeline, directoriesOfPointFilesConvertTogether) {
  std::filesystem::create_directories(dir_ / "parts");
  ASSERT_EQ(runIso("gen plane -n 5000 --seed 1 -o " + quoted(dir_ / "parts" / "a.ply")).exitCode,
            0);
  ASSERT_EQ(runIso("gen plane -n 5000 --seed 2 -o " + quoted(dir_ / "parts" / "b.ply")).exitCode,
            0);
  const auto run =
      runIso("convert -q --json " + quoted(dir_ / "parts") + " -o " + quoted(dir_ / "parts.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out)["points"]["input"], 10000);
}

// The points as LAS (millimetre integers around a UTM-like offset) with colors (red, green, blue)
// of each point as stored, and VLRs and EVLRs.
struct LasScan {
  test::LasSpec spec;
  PointCloud expected;  // the positions the file holds, in double
};

LasScan lasOf(const PointCloud& points, int minor, int format,
              const std::function<std::array<uint16_t, 3>(size_t)>& color) {
  LasScan scan;
  scan.spec = {.minor = minor,
               .format = format,
               .scale = glm::dvec3(1e-4),
               .offset = {515000.0, 4918000.0, 2000.0}};
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::dvec3 q = (points.positions[i] * 10.0) / scan.spec.scale;  // a 10 m sphere
    const std::array<uint16_t, 3> c = color(i);
    scan.spec.points.push_back({int32_t(std::lround(q.x)), int32_t(std::lround(q.y)),
                                int32_t(std::lround(q.z)), c[0], c[1], c[2]});
    const test::LasPoint& p = scan.spec.points.back();
    scan.expected.positions.push_back(glm::dvec3(p.x, p.y, p.z) * scan.spec.scale +
                                      scan.spec.offset);
  }
  return scan;
}

constexpr std::string_view kUtm12Wkt =
    R"(PROJCS["WGS 84 / UTM zone 12N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",)"
    R"(6378137,298.257223563]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],)"
    R"(PROJECTION["Transverse_Mercator"],PARAMETER["central_meridian",-111],UNIT["metre",1],)"
    R"(AUTHORITY["EPSG","32612"]])";

// The coordinate system of LAS inputs goes into the file's metadata (the first input's, with the
// inputs that declare another named), is said while converting and shown by `iso info`.
TEST_F(CliPipeline, theCoordinateSystemOfLasInputsIsKeptAndShown) {
  const PointCloud sphere = readPointFile(dir_ / "sphere.ply");
  PointCloud first, second;
  for (size_t i = 0; i < sphere.size(); ++i)
    (i % 2 == 0 ? first : second).positions.push_back(sphere.positions[i]);
  const auto none = [](size_t) { return std::array<uint16_t, 3>{}; };
  LasScan a = lasOf(first, 4, 6, none);
  a.spec.vlrs = {test::lasGeoAsciiRecord("WGS 84 / UTM zone 12N|"),
                 test::lasGeoKeysRecord({{3072, 0, 1, 32612}, {3073, 34737, 22, 0}})};
  a.spec.evlrs = {test::lasWktRecord(kUtm12Wkt)};
  LasScan b = lasOf(second, 2, 1, none);
  b.spec.vlrs = {test::lasGeoKeysRecord({{3072, 0, 1, 32613}})};
  test::writeFile(dir_ / "a.las", test::makeLas(a.spec).bytes());
  test::writeFile(dir_ / "b.las", test::makeLas(b.spec).bytes());
  const std::string a_las = (dir_ / "a.las").string(), b_las = (dir_ / "b.las").string();

  auto run = runIso("convert --progress none " + quoted(dir_ / "a.las") + " " +
                    quoted(dir_ / "b.las") + " -o " + quoted(dir_ / "ab.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.err.find("coordinate system: EPSG:32612, \"WGS 84 / UTM zone 12N\", OGC WKT (" +
                         std::to_string(kUtm12Wkt.size()) + " characters), from " + a_las +
                         " (kept in the file's metadata)"),
            std::string::npos)
      << run.err;
  EXPECT_NE(run.err.find("warning: " + b_las + " declares another coordinate system than " + a_las),
            std::string::npos)
      << run.err;
  run = runIso("info --json " + quoted(dir_ / "ab.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json info = nlohmann::json::parse(run.out);
  const nlohmann::json expected = {
      {"wkt", kUtm12Wkt},
      {"epsg", 32612},
      {"name", "WGS 84 / UTM zone 12N"},
      {"source", "VLR LASF_Projection 34735 (GeoTIFF keys), EVLR LASF_Projection 2112 (OGC WKT)"},
      {"input", a_las},
      {"differing_inputs", {b_las}}};
  EXPECT_EQ(info["crs"], expected);
  EXPECT_EQ(info["metadata"]["crs"], expected);
  EXPECT_EQ(
      info["metadata"]["inputs"][1]["crs"],
      nlohmann::json({{"epsg", 32613}, {"source", "VLR LASF_Projection 34735 (GeoTIFF keys)"}}));
  run = runIso("info " + quoted(dir_ / "ab.iso"));
  EXPECT_NE(run.out.find("crs         EPSG:32612, \"WGS 84 / UTM zone 12N\", OGC WKT"),
            std::string::npos)
      << run.out;

  // Quiet: the warning only. One input: no warning, nothing differs. A PLY: no coordinate system.
  run = runIso("convert -q -f " + quoted(dir_ / "b.las") + " " + quoted(dir_ / "a.las") + " -o " +
               quoted(dir_ / "ab.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(run.err, "warning: " + a_las + " declares another coordinate system than " + b_las +
                         ": the file's \"crs\" is the first one's (each input's is in its "
                         "\"inputs\" entry)\n");
  run = runIso("convert --progress none -f " + quoted(dir_ / "a.las") + " -o " +
               quoted(dir_ / "a.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(run.err.find("warning"), std::string::npos) << run.err;
  EXPECT_FALSE(
      nlohmann::json::parse(runIso("info --json " + quoted(dir_ / "a.iso")).out)["crs"].contains(
          "differing_inputs"));
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const nlohmann::json plain =
      nlohmann::json::parse(runIso("info --json " + quoted(dir_ / "s.iso")).out);
  EXPECT_TRUE(plain["crs"].is_null());
  EXPECT_FALSE(plain["metadata"].contains("crs"));
}

// LAS colors stored as 8-bit codes times 256 come back as those codes: in the surface's corners
// (white is 255, not 254) and in the kept points.
TEST_F(CliPipeline, eightBitColorsTimes256ComeBackExactlyInTheSurfaceAndKeptPoints) {
  const PointCloud sphere = readPointFile(dir_ / "sphere.ply");
  const auto code = [](size_t i, int channel) { return uint16_t((i * (1 + 40 * channel)) % 256); };
  LasScan varied = lasOf(sphere, 2, 2, [&](size_t i) {
    return std::array<uint16_t, 3>{uint16_t(code(i, 0) * 256), uint16_t(code(i, 1) * 256),
                                   uint16_t(code(i, 2) * 256)};
  });
  for (size_t i = 0; i < sphere.size(); ++i)
    varied.expected.colors.emplace_back(srgb8ToLinear(uint8_t(code(i, 0))),
                                        srgb8ToLinear(uint8_t(code(i, 1))),
                                        srgb8ToLinear(uint8_t(code(i, 2))));
  test::writeFile(dir_ / "varied.las", test::makeLas(varied.spec).bytes());
  auto run = runIso("convert -q --keep-points --point-bits 30 " + quoted(dir_ / "varied.las") +
                    " -o " + quoted(dir_ / "varied.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  ASSERT_EQ(
      runIso("export " + quoted(dir_ / "varied.iso") + " --points " + quoted(dir_ / "kept.ply"))
          .exitCode,
      0);
  test::expectSamePoints(varied.expected, readPointFile(dir_ / "kept.ply"), 1e-6, 0);

  const LasScan white = lasOf(sphere, 4, 7, [](size_t) {
    return std::array<uint16_t, 3>{65280, 65280, 65280};
  });
  test::writeFile(dir_ / "white.las", test::makeLas(white.spec).bytes());
  run = runIso("convert --progress none " + quoted(dir_ / "white.las") + " -o " +
               quoted(dir_ / "white.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.err.find("its colors are 8-bit codes times 256 (every low byte 0): read as 8-bit "
                         "codes"),
            std::string::npos)
      << run.err;
  const SurfaceModel surface = SurfaceModel::load(Reader::open(dir_ / "white.iso"));
  ASSERT_TRUE(surface.hasColors());
  ASSERT_FALSE(surface.corners().color.empty());
  size_t notWhite = 0;
  for (const std::array<float, 3>& color : surface.corners().color)
    for (float channel : color) notWhite += linearToSrgb8(channel) != 255 ? 1 : 0;
  EXPECT_EQ(notWhite, 0u);
}

}  // namespace
}  // namespace iso
