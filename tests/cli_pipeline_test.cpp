// `iso gen`, `iso convert` and `iso eval` run as a user would: outputs, reports, exit codes, and
// clear errors for bad input that leave nothing behind.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <map>
#include <numbers>
#include <functional>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <tuple>
#include <vector>

#include <cstring>

#include <glm/geometric.hpp>

#include "iso/points.h"
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
  EXPECT_EQ(info["metadata"]["parameters"]["leaf_points"], 6);
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

TEST_F(CliPipeline, genWritesLasByItsExtensionAndRefusesOtherExtensions) {
  auto run = runIso("gen sphere -n 5000 --seed 3 --offset 515000,4918000,300 -o " +
                    quoted(dir_ / "sphere.las"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("LAS 1.2 holds no normals"), std::string::npos) << run.out;
  const PointCloud las = readPointFile(dir_ / "sphere.las");
  run = runIso("gen sphere -n 5000 --seed 3 --offset 515000,4918000,300 -o " +
               quoted(dir_ / "same.ply"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const PointCloud ply = readPointFile(dir_ / "same.ply");
  ASSERT_EQ(las.size(), ply.size());
  EXPECT_FALSE(las.hasNormals());
  for (size_t i = 0; i < las.size(); ++i)
    ASSERT_LT(glm::length(las.positions[i] - ply.positions[i]), 1e-6) << i;
  for (const char* name : {"sphere.xyz", "sphere"}) {
    run = runIso("gen sphere -n 100 -o " + quoted(dir_ / name));
    EXPECT_EQ(run.exitCode, 2) << name;
    EXPECT_NE(run.err.find("write .ply or .las"), std::string::npos) << run.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / name)) << name;
  }
}

TEST_F(CliPipeline, convertWritesTheSameBytesOnAnyNumberOfThreads) {
  // Without input normals, so that estimation and orientation run too.
  const auto gen = runIso("gen torus -n 30000 --seed 5 --no-normals -o " + quoted(dir_ / "t.ply"));
  ASSERT_EQ(gen.exitCode, 0);
  std::string bytes[3];
  for (int threads : {1, 2, 0}) {
    const auto out = dir_ / ("t" + std::to_string(threads) + ".iso");
    // Small orientation blocks, so that components are aligned across blocks too, in chunks of
    // the point stages of at most 6,990 points.
    const auto run =
        runIso("convert -q --orient-block-points 512 --chunk-points 6990 --threads " +
               std::to_string(threads) + " " + quoted(dir_ / "t.ply") + " -o " + quoted(out));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    bytes[threads] = test::slurp(out);
  }
  EXPECT_GT(bytes[1].size(), 1000u);
  EXPECT_TRUE(bytes[1] == bytes[2]) << "1 thread and 2 threads differ";
  EXPECT_TRUE(bytes[1] == bytes[0]) << "1 thread and all cores differ";
}

TEST_F(CliPipeline, tinyChunksOfThePointStagesGiveTheSameFileAsOneChunk) {
  const auto gen =
      runIso("gen torus -n 60000 --noise 0.3 --no-normals -o " + quoted(dir_ / "t.ply"));
  ASSERT_EQ(gen.exitCode, 0);
  std::string bytes[2];
  nlohmann::json reports[2];
  const char* budgets[2] = {"--chunk-points 256", "--memory 8G"};
  for (int b = 0; b < 2; ++b) {
    const auto out = dir_ / ("t" + std::to_string(b) + ".iso");
    const auto run = runIso(std::string("convert -q --json --orient-block-points 256 ") +
                            budgets[b] + " --tmp " + quoted(dir_.path()) + " " +
                            quoted(dir_ / "t.ply") + " -o " + quoted(out));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    reports[b] = nlohmann::json::parse(run.out);
    bytes[b] = test::slurp(out);
  }
  EXPECT_GE(reports[0]["out_of_core"]["chunks"].get<int>(), 150);
  EXPECT_EQ(reports[1]["out_of_core"]["chunks"].get<int>(), 1);
  EXPECT_GT(reports[0]["out_of_core"]["temporary_bytes_peak"].get<uint64_t>(), 60000u * 24);
  EXPECT_TRUE(bytes[0] == bytes[1]) << "the chunks changed the output";
  for (const auto& entry : std::filesystem::directory_iterator(dir_.path()))
    EXPECT_NE(entry.path().extension(), ".isotmp") << "left behind: " << entry.path();
}

TEST_F(CliPipeline, aTemporaryDiskLimitIsKeptOrTheConversionStopsWithNothingWritten) {
  ASSERT_EQ(runIso("gen torus -n 100000 --noise 0.3 -o " + quoted(dir_ / "t.ply")).exitCode, 0);
  const std::string convert = "convert -q --json --chunk-points 256 --tmp " + quoted(dir_.path()) +
                              " " + quoted(dir_ / "t.ply") + " -o " + quoted(dir_ / "t.iso");
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

TEST_F(CliPipeline, badMemoryIsRefused) {
  for (const char* options : {"--memory lots", "--memory -2G", "--memory 0", "--chunk-points 0"}) {
    const auto run = runIso(std::string("convert ") + options + " " + quoted(dir_ / "sphere.ply") +
                            " -o " + quoted(dir_ / "x.iso"));
    EXPECT_EQ(run.exitCode, 2) << options << run.err;
    EXPECT_NE(run.err.find(std::string(options).substr(0, 8)), std::string::npos) << run.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / "x.iso"));
  }
  // Budgets below the smallest one a conversion keeps to (its peak within --memory + 10 %) are
  // refused with it, before anything is read; an old output stays as it was.
  std::ofstream(dir_ / "old.iso") << "old";
  for (const char* memory : {"200M", "511M", "523263K", "4M"}) {
    const auto run = runIso(std::string("convert -f --memory ") + memory + " " +
                            quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "old.iso"));
    EXPECT_EQ(run.exitCode, 2) << memory << run.err;
    EXPECT_NE(run.err.find(std::string("--memory ") + memory +
                           ": below the smallest budget a conversion keeps to, 512M"),
              std::string::npos)
        << run.err;
    EXPECT_EQ(run.err.find("read "), std::string::npos) << run.err;
    EXPECT_EQ(test::slurp(dir_ / "old.iso"), "old");
  }
  const auto run = runIso("convert -q --memory 512M " + quoted(dir_ / "sphere.ply") + " -o " +
                          quoted(dir_ / "x.iso"));
  EXPECT_EQ(run.exitCode, 0) << run.err;
  EXPECT_TRUE(std::filesystem::exists(dir_ / "x.iso"));
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
  const std::vector<std::string> stages = {"read",  "distribute", "points",          "orient",
                                           "index", "octree",     "passive+balance", "corners",
                                           "lod",   "write",      "accuracy",        "visibility"};
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

TEST_F(CliPipeline, bakeLightsAFileAndRefusesWhatItCannotDo) {
  auto run =
      runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "sphere.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto write = [&](const char* name, const std::string& text) {
    std::ofstream(dir_ / name) << text;
    return quoted(dir_ / name);
  };
  const std::string scene =
      write("scene.json", R"({"lights": [{"type": "point", "position": [2, 3, 4],)"
                          R"( "falloff": "inverse_square", "intensity": 20}]})");
  const std::string bake = "bake " + quoted(dir_ / "sphere.iso") + " -o ";
  run = runIso(bake + quoted(dir_ / "lit.iso") + " --scene " + scene + " --bounces 1 --bake-rays 8");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("light bake:"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("light map error"), std::string::npos) << run.out;
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "lit.iso")).exitCode, 0);
  run = runIso("info --json " + quoted(dir_ / "lit.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json info = nlohmann::json::parse(run.out);
  EXPECT_GT(info["lighting"]["chunks"].get<int>(), 0);
  EXPECT_EQ(info["metadata"]["lighting"]["bounces"], 1);
  EXPECT_EQ(info["metadata"]["lighting"]["lights"][0]["falloff"], "inverse_square");
  // The same through the conversion: the same lighting chunks.
  run = runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "both.iso") +
               " --bake-light " + scene + " --bounces 1 --bake-rays 8");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  {
    const Reader a = Reader::open(dir_ / "lit.iso"), b = Reader::open(dir_ / "both.iso");
    ASSERT_EQ(a.chunks().size(), b.chunks().size());
    for (const ChunkInfo& c : a.chunks()) {
      if (c.kind != 5) continue;
      EXPECT_TRUE(std::ranges::equal(a.bytes().subspan(c.offset, c.storedSize),
                                     b.bytes().subspan(b.chunk(c.id).offset,
                                                       b.chunk(c.id).storedSize)));
    }
  }
  // An existing output without -f, the input as output, a scene without lights, impossible
  // options: refused before any work, the old file left as it was.
  const std::vector<std::byte> old(64, std::byte{7});
  test::writeFile(dir_ / "old.iso", old);
  run = runIso(bake + quoted(dir_ / "old.iso") + " --scene " + scene);
  EXPECT_EQ(run.exitCode, 1) << run.err;
  EXPECT_NE(run.err.find("old.iso"), std::string::npos) << run.err;
  run = runIso(bake + quoted(dir_ / "sphere.iso") + " -f --scene " + scene);
  EXPECT_EQ(run.exitCode, 1) << run.err;
  const std::string dark = write("dark.json", R"({"lights": []})");
  const std::string odd = write("odd.json", R"({"lights": [{"type": "point", "position": [1, 2, 3], "falloff": "cubic"}]})");
  for (const std::string& options :
       {" --scene " + dark, " --scene " + odd, " --scene " + scene + " --bounces 17",
        " --scene " + scene + " --bake-rays 0", " --scene " + quoted(dir_ / "missing.json")}) {
    run = runIso(bake + quoted(dir_ / "old.iso") + " -f" + options);
    EXPECT_NE(run.exitCode, 0) << options;
    EXPECT_TRUE(test::readFile(dir_ / "old.iso") == old) << options;
  }
  run = runIso("convert -f -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "old.iso") +
               " --bounces 2");
  EXPECT_EQ(run.exitCode, 2) << "--bounces without --bake-light\n" << run.err;
  EXPECT_TRUE(test::readFile(dir_ / "old.iso") == old);
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
  // A level set that OpenVDB's own vdb_print reads; in builds without OpenVDB, a usage error
  // that says so.
  run = runIso("export " + quoted(dir_ / "s.iso") + " --vdb " + quoted(dir_ / "s.vdb"));
  if (ISO_WITH_OPENVDB) {
    ASSERT_EQ(run.exitCode, 0) << run.err;
    EXPECT_NE(run.out.find("active voxels"), std::string::npos) << run.out;
    EXPECT_EQ(std::system(("vdb_print " + quoted(dir_ / "s.vdb") + " > /dev/null").c_str()), 0);
  } else {
    EXPECT_EQ(run.exitCode, 2);
    EXPECT_NE(run.err.find("--vdb: this build of iso has no OpenVDB"), std::string::npos)
        << run.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / "s.vdb"));
  }
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

TEST_F(CliPipeline, exportWritesGlbMeshesThatTheKhronosValidatorAccepts) {
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const std::string iso = quoted(dir_ / "s.iso");
  auto run = runIso("export --json " + iso + " --mesh " + quoted(dir_ / "full.glb"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json full = nlohmann::json::parse(run.out)["mesh"];
  EXPECT_EQ(full["format"], "glb");
  EXPECT_TRUE(full["glb"]["quantized_positions"].get<bool>());
  EXPECT_TRUE(full["glb"]["normals"].get<bool>());
  EXPECT_EQ(full["glb"]["bytes"].get<uint64_t>(), std::filesystem::file_size(dir_ / "full.glb"));
  run = runIso("export --json " + iso + " --mesh " + quoted(dir_ / "plain.glb") + " --no-meshopt");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_GT(std::filesystem::file_size(dir_ / "plain.glb"),
            2 * std::filesystem::file_size(dir_ / "full.glb"));
  // A coarser cut, simplified within 1 % of the radius: far fewer triangles, within the error.
  run = runIso("export --json " + iso + " --mesh " + quoted(dir_ / "lod.glb") +
               " --level 5 --max-error 0.01");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json lod = nlohmann::json::parse(run.out)["mesh"];
  EXPECT_EQ(lod["level"], 5);
  EXPECT_LT(lod["triangles"].get<uint64_t>(), full["triangles"].get<uint64_t>() / 4);
  EXPECT_LE(lod["simplified"]["measured_error"].get<double>(), 0.01);
  // The Khronos glTF validator (npm gltf-validator, installed by tools/run setup): no errors.
  const std::filesystem::path web = ISO_WEB_TOOLS_DIR;
  ASSERT_TRUE(std::filesystem::exists(web / "node_modules" / "gltf-validator"))
      << "run tools/run setup (it installs " << web.string() << "'s npm packages)";
  run = test::runCommand("node " + quoted(web / "validate.mjs") + " " + quoted(dir_ / "full.glb") +
                         " " + quoted(dir_ / "plain.glb") + " " + quoted(dir_ / "lod.glb"));
  EXPECT_EQ(run.exitCode, 0) << run.out << run.err;
  size_t files = 0;
  std::istringstream lines(run.out);
  for (std::string line; std::getline(lines, line);) {
    const nlohmann::json report = nlohmann::json::parse(line);
    EXPECT_EQ(report["errors"], 0) << line;
    EXPECT_EQ(report["warnings"], 0) << line;
    ++files;
  }
  EXPECT_EQ(files, 3u);
  // Impossible options: usage errors, nothing written.
  for (const std::string options :
       {"--max-error 0.01", "--mesh x.glb --max-error -1", "--mesh x.glb --max-error nan",
        "--mesh x.glb --level 99", "--mesh x.ply --no-meshopt"}) {
    run = runIso("export " + iso + " " + options);
    EXPECT_EQ(run.exitCode, 2) << options << "\n" << run.err;
  }
  EXPECT_FALSE(std::filesystem::exists("x.glb"));
  EXPECT_FALSE(std::filesystem::exists("x.ply"));
}

TEST_F(CliPipeline, exportWritesATilesetOnlyWhereItMayAndTheValidatorAcceptsItsTiles) {
  ASSERT_EQ(runIso("convert -q --chunk-nodes 2000 " + quoted(dir_ / "sphere.ply") + " -o " +
                   quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const std::string iso = quoted(dir_ / "s.iso"), out = quoted(dir_ / "tiles");
  auto run = runIso("export --json " + iso + " --tiles " + out + " --tile-leaves 200");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json summary = nlohmann::json::parse(run.out)["tiles"];
  EXPECT_GT(summary["tiles"].get<uint64_t>(), 1u);
  const size_t levels = summary["levels"].size();
  EXPECT_GE(levels, 3u);
  uint64_t triangles = 0;
  for (const auto& l : summary["levels"]) triangles += l["triangles"].get<uint64_t>();
  EXPECT_EQ(triangles, summary["triangles"].get<uint64_t>());
  std::vector<std::string> glbs;
  for (const auto& entry : std::filesystem::directory_iterator(dir_ / "tiles"))
    if (entry.path().extension() == ".glb") glbs.push_back(quoted(entry.path()));
  EXPECT_GT(glbs.size(), 1u);
  const std::filesystem::path web = ISO_WEB_TOOLS_DIR;
  std::string command = "node " + quoted(web / "validate.mjs");
  for (const std::string& glb : glbs) command += " " + glb;
  run = test::runCommand(command);
  EXPECT_EQ(run.exitCode, 0) << run.out << run.err;
  // iso eval measures what the tileset draws against the file: its finest tiles close to the
  // zero set; at every depth each tile within the error it states of the finest tiles below it,
  // and the root within its error of the zero set too (the finest are close to it).
  run = runIso("eval " + iso + " --tiles " + out);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json finest = nlohmann::json::parse(run.out);
  EXPECT_LT(finest["rms_over_spacing"].get<double>(), 0.1);
  for (size_t depth = 0; depth < levels; ++depth) {
    run = runIso("eval " + iso + " --tiles " + out + " --depth " + std::to_string(depth));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    const nlohmann::json cut = nlohmann::json::parse(run.out)["tiles"];
    EXPECT_EQ(cut["to_finest"]["tiles_beyond_their_error"], 0) << depth;
    EXPECT_LE(cut["to_finest"]["max"].get<double>(), cut["geometric_error"].get<double>());
  }
  run = runIso("eval " + iso + " --tiles " + out + " --depth 0");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const nlohmann::json top = nlohmann::json::parse(run.out);
  EXPECT_EQ(top["tiles"]["tiles"], 1);
  EXPECT_LE(top["max"].get<double>(), top["tiles"]["geometric_error"].get<double>());
  run = runIso("export " + iso + " --tile-leaves 4 --tiles " + quoted(dir_ / "t2"));
  EXPECT_EQ(run.exitCode, 2);
  EXPECT_NE(run.err.find("--tile-leaves"), std::string::npos) << run.err;
  std::printf("finest tiles: RMS %.3f spacings; root tile: max %.4g, stated %.4g\n",
              finest["rms_over_spacing"].get<double>(), top["max"].get<double>(),
              top["tiles"]["geometric_error"].get<double>());
  run = runIso("eval " + iso + " --depth 0 --shape sphere");
  EXPECT_EQ(run.exitCode, 2);
  EXPECT_NE(run.err.find("--depth"), std::string::npos) << run.err;
  run = runIso("eval " + iso + " --tiles " + quoted(dir_ / "nowhere"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("tileset.json"), std::string::npos) << run.err;
  // Not over an existing directory without --force (it stays as it was); with it, replaced.
  std::filesystem::remove(dir_ / "tiles" / "tileset.json");
  run = runIso("export " + iso + " --tiles " + out);
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("tiles"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "tiles" / "tileset.json"));
  run = runIso("export -f " + iso + " --tiles " + out);
  EXPECT_EQ(run.exitCode, 0) << run.err;
  EXPECT_TRUE(std::filesystem::exists(dir_ / "tiles" / "tileset.json"));
  // A file in the way: an error naming it. Nothing is left beside it.
  run = runIso("export -f " + iso + " --tiles " + quoted(dir_ / "s.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("not a directory"), std::string::npos) << run.err;
  for (const auto& entry : std::filesystem::directory_iterator(dir_.path()))
    EXPECT_EQ(entry.path().filename().string().find(".isotmp"), std::string::npos) << entry.path();
}

// A tileset's directory named with a trailing slash ("tiles/", "tiles//") is the directory
// "tiles": made new, refused when it exists, replaced with --force, and the same files as without.
TEST_F(CliPipeline, aTilesetDirectoryNamedWithATrailingSlashIsWrittenAsWithout) {
  namespace fs = std::filesystem;
  ASSERT_EQ(runIso("convert -q --chunk-nodes 2000 " + quoted(dir_ / "sphere.ply") + " -o " +
                   quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const std::string iso = quoted(dir_ / "s.iso");
  const auto filesIn = [](const fs::path& dir) {
    std::map<std::string, std::string> files;
    for (const auto& entry : fs::directory_iterator(dir))
      files[entry.path().filename().string()] = test::slurp(entry.path());
    return files;
  };
  auto run = runIso("export " + iso + " --tiles " + quoted(dir_ / "plain"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto expected = filesIn(dir_ / "plain");
  ASSERT_TRUE(expected.contains("tileset.json"));
  const std::string slashed = quoted(fs::path((dir_ / "slashed").string() + "/"));
  run = runIso("export " + iso + " --tiles " + slashed);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(filesIn(dir_ / "slashed"), expected);
  // There now: refused without --force, untouched; replaced with it (two slashes too).
  fs::remove(dir_ / "slashed" / "tileset.json");
  run = runIso("export " + iso + " --tiles " + slashed);
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir_ / "slashed").string() + ": exists (use --force to replace it)"),
            std::string::npos)
      << run.err;
  EXPECT_FALSE(fs::exists(dir_ / "slashed" / "tileset.json"));
  run = runIso("export -f " + iso + " --tiles " +
               quoted(fs::path((dir_ / "slashed").string() + "//")));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(filesIn(dir_ / "slashed"), expected);
  // A file in the way is named, and nothing is left beside it.
  run =
      runIso("export -f " + iso + " --tiles " + quoted(fs::path((dir_ / "s.iso").string() + "/")));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir_ / "s.iso").string() + ": exists and is not a directory"),
            std::string::npos)
      << run.err;
  for (const auto& entry : fs::directory_iterator(dir_.path()))
    EXPECT_EQ(entry.path().filename().string().find(".isotmp"), std::string::npos) << entry.path();
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
    if (chunk["kind"] == "points" && at == 0) {  // the first: points, not a subsample of them
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
  ASSERT_EQ(
      runIso("gen cube -n 4000 --half-size 0.99 --seed 5 -o " + quoted(dir_ / "cube.ply")).exitCode,
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
  EXPECT_EQ(
      runIso("eval " + iso + " --points " + ply + " --seen-through " + quoted(dir_ / "other.ply"))
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
  std::vector<std::string> args = {binary,         "convert", "-q",           "-f",
                                   input.string(), "-o",      output.string()};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t child = 0;
  if (posix_spawn(&child, binary.c_str(), nullptr, nullptr, argv.data(), environ) != 0) return "";
  std::string temporary;
  for (int status = 0; temporary.empty();) {
    const std::string prefix = "." + output.filename().string() + "." + std::to_string(child) + "-";
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
  const auto run =
      runIso("convert -f " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "again.iso"));
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
  // Points 10^20 apart: their cube is larger than an .iso frame holds (2^64).
  std::ofstream(dir_ / "huge.xyz") << "0 0 0\n1e20 0 0\n0 1e20 0\n1e20 1e20 0\n5e19 3e19 0\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"missing.ply", "missing.ply"},
      {"cut.ply", "file ends after"},
      {"empty.ply", "no points"},
      {"scan.laz", "LAZ"},
      {"one.xyz", "at least 3 distinct points"},
      {"same.xyz", "the input has 1"},
      {"two.xyz", "the input has 2"},
      {"line.xyz", "one line"},
      {"huge.xyz", "beyond what an .iso file holds: frame size is not within 2^-64 to 2^64"}};
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

TEST_F(CliPipeline, convertReportsTheStraysItRemovesAndWritesThemOnRequest) {
  // The sphere with a bird of 12 points and two single returns: the report and the printed lines
  // count them, --write-strays writes exactly them, and --keep-outliers keeps them.
  PointCloud cloud = readPointFile(dir_ / "sphere.ply");
  const size_t sphere = cloud.size();
  std::vector<glm::dvec3> strays = {{3.0, 0.0, 0.0}, {0.0, -40.0, 2.0}};
  for (int i = 0; i < 12; ++i)  // inside the frame's cube, beside the sphere
    strays.push_back({0.85 + 0.02 * (i % 3), 0.85 + 0.005 * i, 0.02 * (i % 4)});
  for (const glm::dvec3& p : strays) {
    cloud.positions.push_back(p);
    cloud.normals.push_back(glm::vec3(0.0f, 0.0f, 1.0f));
  }
  writePly(dir_ / "with.ply", cloud);
  const auto run = runIso("convert --progress none " + quoted(dir_ / "with.ply") + " -o " +
                          quoted(dir_ / "with.iso") + " --report " + quoted(dir_ / "r.json") +
                          " --write-strays " + quoted(dir_ / "strays.ply"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("14 strays removed"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("strays: 14 in groups of fewer than 64 points"), std::string::npos);
  const nlohmann::json report = nlohmann::json::parse(test::slurp(dir_ / "r.json"));
  EXPECT_EQ(report["points"]["outliers_removed"], strays.size());
  EXPECT_EQ(report["points"]["used"], sphere);
  const PointCloud written = readPointFile(dir_ / "strays.ply");
  ASSERT_EQ(written.size(), strays.size());
  std::vector<glm::dvec3> got = written.positions;
  const auto less = [](const glm::dvec3& a, const glm::dvec3& b) {
    return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
  };
  std::sort(got.begin(), got.end(), less);
  std::sort(strays.begin(), strays.end(), less);
  EXPECT_EQ(got, strays);  // positions are written as doubles: exactly the input's
  EXPECT_EQ(written.normals.size(), strays.size());
  // iso eval leaves the same strays out of what it measures (none seen through), unless told.
  const auto eval = runIso("eval --visibility " + quoted(dir_ / "with.iso") + " --points " +
                           quoted(dir_ / "with.ply"));
  ASSERT_EQ(eval.exitCode, 0) << eval.err;
  const nlohmann::json measured = nlohmann::json::parse(eval.out);
  EXPECT_EQ(measured["strays_left_out"], strays.size());
  EXPECT_EQ(measured["visibility"]["seen_through"], 0);
  const auto all = runIso("eval --visibility --keep-outliers " + quoted(dir_ / "with.iso") +
                          " --points " + quoted(dir_ / "with.ply"));
  ASSERT_EQ(all.exitCode, 0) << all.err;
  EXPECT_EQ(nlohmann::json::parse(all.out)["strays_left_out"], 0);
  EXPECT_GE(nlohmann::json::parse(all.out)["visibility"]["seen_through"].get<int>(), 1);

  const auto kept = runIso("convert -q --json --keep-outliers " + quoted(dir_ / "with.ply") +
                           " -o " + quoted(dir_ / "kept.iso"));
  ASSERT_EQ(kept.exitCode, 0) << kept.err;
  EXPECT_EQ(nlohmann::json::parse(kept.out)["points"]["used"], cloud.size());
  const auto both = runIso("convert -q --keep-outliers " + quoted(dir_ / "with.ply") + " -o " +
                           quoted(dir_ / "k2.iso") + " --write-strays " + quoted(dir_ / "s2.ply"));
  EXPECT_EQ(both.exitCode, 2) << both.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "k2.iso"));
}

TEST_F(CliPipeline, impossibleOptionsAreUsageErrors) {
  for (const std::string options :
       {"--max-depth 30", "--leaf-points 0", "--normal-bits 10", "--fit cubic", "--orient sideways",
        "--smoothing -1", "--tolerance nan", "--corner-fit -1", "--corner-fit 17"}) {
    const auto run = runIso("convert -q " + options + " " + quoted(dir_ / "sphere.ply") + " -o " +
                            quoted(dir_ / "x.iso"));
    EXPECT_EQ(run.exitCode, 2) << options << ": " << run.err;
    EXPECT_FALSE(run.err.empty());
    EXPECT_FALSE(std::filesystem::exists(dir_ / "x.iso"));
  }
  EXPECT_EQ(runIso("gen -o " + quoted(dir_ / "x.ply")).exitCode, 2);  // no shape
  for (const char* count : {"-5", "0", "4294967297", "99999999999999999999"}) {
    const auto run =
        runIso(std::string("gen sphere -n ") + count + " -o " + quoted(dir_ / "x.ply"));
    EXPECT_EQ(run.exitCode, 2) << count << ": " << run.err;
    EXPECT_NE(run.err.find("--count"), std::string::npos) << run.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.ply"));
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

// ---- Paths, sizes and interruptions: what a user meets first.

namespace fs = std::filesystem;

void put(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

// The iso temporary files (".NAME.PID-N.isotmp") anywhere under `directory`.
std::vector<std::string> temporariesUnder(const fs::path& directory) {
  std::vector<std::string> found;
  for (const auto& entry : fs::recursive_directory_iterator(directory))
    if (entry.path().extension() == ".isotmp") found.push_back(entry.path().string());
  return found;
}

// Run `iso ARGUMENTS` as runIso does, with every file it writes limited to `maxFileBytes`
// (RLIMIT_FSIZE, SIGXFSZ ignored: a write past the limit fails with EFBIG, as one on a full disk
// fails with ENOSPC).
test::CommandResult runIsoWithFileLimit(const std::string& arguments, uint64_t maxFileBytes) {
  test::TempDir dir;
  const std::string command = std::string(ISO_BINARY) + " " + arguments + " >" +
                              quoted(dir / "out") + " 2>" + quoted(dir / "err");
  const pid_t child = fork();
  if (child == 0) {
    const rlimit limit{maxFileBytes, maxFileBytes};
    setrlimit(RLIMIT_FSIZE, &limit);
    signal(SIGXFSZ, SIG_IGN);
    execl("/bin/sh", "sh", "-c", command.c_str(), nullptr);
    _exit(127);
  }
  int status = 0;
  waitpid(child, &status, 0);
  test::CommandResult run;
  run.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.out = test::slurp(dir / "out");
  run.err = test::slurp(dir / "err");
  return run;
}

// Start `iso ARGUMENTS...` with stderr into `err` and stdout discarded; `ignored`, when not 0, is
// a signal the process starts ignoring (as under nohup).
pid_t startIso(const std::vector<std::string>& arguments, const fs::path& err, int ignored = 0) {
  std::vector<std::string> args = {ISO_BINARY};
  args.insert(args.end(), arguments.begin(), arguments.end());
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t child = fork();
  if (child == 0) {
    if (ignored != 0) signal(ignored, SIG_IGN);
    const int errFd = open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int nullFd = open("/dev/null", O_WRONLY);
    dup2(errFd, 2);
    dup2(nullFd, 1);
    execv(argv[0], argv.data());
    _exit(127);
  }
  return child;
}

// Poll until `ready` holds (true) or the process ends first (false).
bool waitUntil(pid_t pid, const std::function<bool()>& ready) {
  while (!ready()) {
    if (waitpid(pid, nullptr, WNOHANG) == pid) return false;
    usleep(1000);
  }
  return true;
}

bool hasEntryStartingWith(const fs::path& directory, const std::string& prefix) {
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(directory, error))
    if (entry.path().filename().string().starts_with(prefix)) return true;
  return false;
}

std::string lastLine(const std::string& text) {
  const size_t end = text.find_last_not_of('\n');
  if (end == std::string::npos) return "";
  const size_t begin = text.rfind('\n', end);
  return text.substr(begin == std::string::npos ? 0 : begin + 1,
                     end - (begin == std::string::npos ? 0 : begin + 1) + 1);
}

TEST_F(CliPipeline, aMissingTemporaryDirectoryIsMadeAndRemovedAfterwards) {
  const auto convert = [&](const fs::path& tmp, const std::string& more) {
    return runIso("convert -q " + more + " --tmp " + quoted(tmp) + " " +
                  quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"));
  };
  // Made with its missing parents, and removed when the conversion succeeds ...
  auto run = convert(dir_ / "made" / "deeper" / "tmp", "");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "s.iso")).exitCode, 0);
  EXPECT_FALSE(fs::exists(dir_ / "made"));
  // ... and when it fails after writing temporary files there.
  run = convert(dir_ / "made" / "tmp", "-f --max-temp 1K");
  EXPECT_EQ(run.exitCode, 1) << run.err;
  EXPECT_NE(run.err.find("--max-temp"), std::string::npos) << run.err;
  EXPECT_FALSE(fs::exists(dir_ / "made"));
  // A directory that was there stays, with what it holds; only what was made goes.
  fs::create_directory(dir_ / "had");
  put(dir_ / "had" / "mine", "mine");
  run = convert(dir_ / "had" / "new", "-f");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_ / "had"), fs::directory_iterator()), 1);
  EXPECT_EQ(test::slurp(dir_ / "had" / "mine"), "mine");
  // What cannot be made is named, and nothing is written.
  fs::remove(dir_ / "s.iso");
  run = convert(dir_ / "sphere.ply" / "tmp", "");
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir_ / "sphere.ply").string() + ": is not a directory (--tmp)"),
            std::string::npos)
      << run.err;
  test::ReadOnlyDirectory locked(dir_ / "locked");
  if (locked.ok()) {
    locked.lock();
    run = convert(dir_ / "locked" / "a" / "b", "");
    EXPECT_EQ(run.exitCode, 1);
    EXPECT_NE(run.err.find((dir_ / "locked" / "a").string() +
                           ": cannot make this directory for "
                           "--tmp " +
                           (dir_ / "locked" / "a" / "b").string() + ": "),
              std::string::npos)
        << run.err;
  }
  EXPECT_FALSE(fs::exists(dir_ / "s.iso"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());
}

TEST_F(CliPipeline, everyByteSizeOptionRefusesOverflowNegativeNaNAndGarbage) {
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const std::string convert =
      "convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "x.iso");
  const std::string view = "view " + quoted(dir_ / "s.iso") +
                           " --cpu --width 16 --height 16 --out " + quoted(dir_ / "x.png");
  const std::pair<std::string, std::string> options[] = {{convert, "--memory"},
                                                         {convert, "--max-temp"},
                                                         {view, "--vram"},
                                                         {view, "--upload-per-frame"}};
  const std::pair<std::string, std::string> values[] = {{"99999999999999999999G", "more than 2^64"},
                                                        {"16777216T", "more than 2^64"},
                                                        {"-2G", "not positive"},
                                                        {"0.5", "less than one byte"},
                                                        {"nan", "not a number"},
                                                        {"2X", "not a number"}};
  for (const auto& [command, option] : options)
    for (const auto& [value, why] : values) {
      const auto run = runIso(command + " " + option + " '" + value + "'");
      EXPECT_EQ(run.exitCode, 2) << option << " " << value << ": " << run.err;
      EXPECT_NE(run.err.find(option + " '" + value + "': " + why), std::string::npos) << run.err;
    }
  EXPECT_FALSE(fs::exists(dir_ / "x.iso"));
  EXPECT_FALSE(fs::exists(dir_ / "x.png"));
  // The largest size there is, exactly, and units in either case.
  auto run = runIso(convert + " --json --max-temp 18446744073709551615 --memory 512mib");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out)["out_of_core"]["temporary_disk_limit"].get<uint64_t>(),
            18446744073709551615u);
}

TEST_F(CliPipeline, aMissingOutputDirectoryIsNamedByEveryCommandThatWrites) {
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const fs::path missing = dir_ / "no" / "such";
  const std::string ply = quoted(dir_ / "sphere.ply"), iso = quoted(dir_ / "s.iso");
  const std::string out = quoted(missing / "out");
  std::vector<std::string> commands = {
      "convert " + ply + " -o " + out,
      "convert " + ply + " -o " + out + " --tmp " + quoted(dir_.path()),
      "convert " + ply + " -o " + quoted(dir_ / "x.iso") + " --report " + out,
      "export " + iso + " --mesh " + out,
      "export " + iso + " --points " + out,
      "export " + iso + " --tiles " + out,
      "export " + iso + " --tiles " + out + "/",
      "gen sphere -n 1000 -o " + out,
      "view " + iso + " --cpu --width 16 --height 16 --out " + out,
      "view " + iso + " --cpu --width 16 --height 16 --out " + quoted(dir_ / "x.png") +
          " --screenshot " + out,
      "eval " + iso + " --visibility --points " + ply + " --seen-through " + out};
  if (ISO_WITH_OPENVDB) {
    commands.push_back("export " + iso + " --vdb " + out);
    commands.push_back("export " + iso + " --mesh " + quoted(dir_ / "x.ply") + " --vdb " + out);
  }
  for (const std::string& command : commands) {
    const auto run = runIso(command);
    EXPECT_EQ(run.exitCode, 1) << command;
    EXPECT_NE(run.err.find((missing / "out").string() + ": the directory " + missing.string() +
                           " does not exist"),
              std::string::npos)
        << command << "\n"
        << run.err;
    EXPECT_EQ(run.err.find("--tmp"), std::string::npos) << run.err;
    EXPECT_EQ(run.err.find("read "), std::string::npos) << "work before the check: " << run.err;
  }
  // A part of the path that is a file.
  const auto run = runIso("convert " + ply + " -o " + quoted(dir_ / "sphere.ply" / "out.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir_ / "sphere.ply").string() + " is not a directory"), std::string::npos)
      << run.err;
  for (const char* made : {"x.iso", "x.ply", "x.png", "no"})
    EXPECT_FALSE(fs::exists(dir_ / made)) << made;
}

TEST_F(CliPipeline, outputsThatCannotBeWrittenAreRefusedBeforeAnyWork) {
  ASSERT_EQ(runIso("convert -q " + quoted(dir_ / "sphere.ply") + " -o " + quoted(dir_ / "s.iso"))
                .exitCode,
            0);
  const std::vector<std::byte> input = test::readFile(dir_ / "sphere.ply");
  const std::vector<std::byte> iso = test::readFile(dir_ / "s.iso");
  fs::create_directory(dir_ / "folder");
  const std::string ply = quoted(dir_ / "sphere.ply"), file = quoted(dir_ / "s.iso");
  std::vector<std::pair<std::string, std::string>> cases = {
      {"convert -f " + ply + " -o " + quoted(dir_ / "folder"),
       "is a directory (-o wants a file name)"},
      {"convert -f " + ply + " -o " + ply, "is also an input (-o would replace"},
      {"convert -f " + ply + " -o " + quoted(dir_ / "t.iso") + " --report " + ply,
       "is also an input (--report would replace"},
      {"export -f " + file + " --mesh " + file, "is also an input (--mesh would replace"},
      {"gen sphere -f -n 1000 -o " + quoted(dir_ / "folder"), "is a directory (-o wants"},
      {"eval " + file + " --visibility --points " + ply + " -f --seen-through " + ply,
       "is also an input (--seen-through would replace"},
      {"view " + file + " --cpu --out " + file, "is also an input (--out would replace"}};
  if (ISO_WITH_OPENVDB)
    cases.push_back(
        {"export " + file + " --vdb " + quoted(dir_ / "folder"), "is a directory (--vdb wants"});
  for (const auto& [command, expected] : cases) {
    const auto run = runIso(command);
    EXPECT_EQ(run.exitCode, 1) << command;
    EXPECT_NE(run.err.find(expected), std::string::npos) << command << "\n" << run.err;
    EXPECT_EQ(run.err.find("read "), std::string::npos) << "work before the check: " << run.err;
  }
  // No name, or two outputs of one export named alike: usage errors.
  const auto empty = runIso("convert " + ply + " -o ''");
  EXPECT_EQ(empty.exitCode, 2);
  EXPECT_NE(empty.err.find("-o names no file"), std::string::npos) << empty.err;
  const auto report = runIso("convert " + ply + " -o " + quoted(dir_ / "t.iso") + " --report " +
                             quoted(dir_ / "folder" / ".." / "t.iso"));
  EXPECT_EQ(report.exitCode, 2);
  EXPECT_NE(report.err.find("-o and --report name the same file"), std::string::npos) << report.err;
  const auto twice = runIso("export " + file + " --mesh " + quoted(dir_ / "m.ply") + " --points " +
                            quoted(dir_ / "." / "m.ply"));
  EXPECT_EQ(twice.exitCode, 2);
  EXPECT_NE(twice.err.find("--mesh and --points name the same file"), std::string::npos)
      << twice.err;
  EXPECT_TRUE(test::readFile(dir_ / "sphere.ply") == input);
  EXPECT_TRUE(test::readFile(dir_ / "s.iso") == iso);
  EXPECT_TRUE(fs::is_empty(dir_ / "folder"));
  for (const char* made : {"t.iso", "m.ply"}) EXPECT_FALSE(fs::exists(dir_ / made)) << made;
  // A directory nothing can be written in: refused before any work; its file keeps its bytes.
  test::ReadOnlyDirectory locked(dir_ / "locked");
  if (!locked.ok()) GTEST_SKIP() << "cannot make a read-only directory here";
  put(dir_ / "locked" / "s.iso", "old");
  locked.lock();
  auto run = runIso("convert -f " + ply + " -o " + quoted(dir_ / "locked" / "s.iso"));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("cannot write in the directory " + (dir_ / "locked").string()),
            std::string::npos)
      << run.err;
  EXPECT_EQ(run.err.find("read "), std::string::npos) << run.err;
  const std::string lockedOutput = ISO_WITH_OPENVDB
                                       ? " --vdb " + quoted(dir_ / "locked" / "s.vdb")
                                       : " --points " + quoted(dir_ / "locked" / "p.ply");
  run = runIso("export -f " + file + " --mesh " + quoted(dir_ / "m.ply") + lockedOutput);
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("cannot write in the directory"), std::string::npos) << run.err;
  EXPECT_EQ(test::slurp(dir_ / "locked" / "s.iso"), "old");
  EXPECT_FALSE(fs::exists(dir_ / "m.ply"));
}

TEST_F(CliPipeline, exportWritesAllItsFilesOrNone) {
  if (!ISO_WITH_OPENVDB) GTEST_SKIP() << "this build has no OpenVDB (ISO_WITH_OPENVDB=OFF)";
  ASSERT_EQ(runIso("convert -q --keep-points " + quoted(dir_ / "sphere.ply") + " -o " +
                   quoted(dir_ / "k.iso"))
                .exitCode,
            0);
  const std::string all = "export -f " + quoted(dir_ / "k.iso") + " --points " +
                          quoted(dir_ / "p.ply") + " --mesh " + quoted(dir_ / "m.ply") + " --vdb " +
                          quoted(dir_ / "v.vdb");
  // Written once in full, for their sizes and bytes.
  auto run = runIso(all);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const uint64_t points = fs::file_size(dir_ / "p.ply"), mesh = fs::file_size(dir_ / "m.ply");
  ASSERT_LT(points, mesh);  // the points come first: a limit between the two fails the mesh
  EXPECT_EQ(readPointFile(dir_ / "p.ply").size(), 20000u);
  fs::remove(dir_ / "m.ply");
  fs::remove(dir_ / "v.vdb");
  put(dir_ / "p.ply", "old points");
  // The mesh fails after the points are complete: neither is left, the old file keeps its bytes.
  run = runIsoWithFileLimit(all, (points + mesh) / 2);
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir_ / "m.ply").string() + ": cannot write"), std::string::npos)
      << run.err;
  EXPECT_NE(run.err.find("File too large"), std::string::npos) << run.err;
  EXPECT_EQ(test::slurp(dir_ / "p.ply"), "old points");
  EXPECT_FALSE(fs::exists(dir_ / "m.ply"));
  EXPECT_FALSE(fs::exists(dir_ / "v.vdb"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());
  // A level set that does not fit is an error too, not a cut file (OpenVDB's own writer ignores
  // its stream's errors).
  run = runIsoWithFileLimit("export " + quoted(dir_ / "k.iso") + " --vdb " + quoted(dir_ / "v.vdb"),
                            64 << 10);
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir_ / "v.vdb").string() + ": cannot write: File too large"),
            std::string::npos)
      << run.err;
  EXPECT_FALSE(fs::exists(dir_ / "v.vdb"));
  // Without the limit all three are written, the old file replaced.
  run = runIso(all);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(readPointFile(dir_ / "p.ply").size(), 20000u);
  EXPECT_EQ(fs::file_size(dir_ / "m.ply"), mesh);
  EXPECT_EQ(std::system(("vdb_print " + quoted(dir_ / "v.vdb") + " > /dev/null").c_str()), 0);
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());
}

TEST_F(CliPipeline, anInterruptEndsConvertAndExportWithALineSayingWhatItLeft) {
  ASSERT_EQ(runIso("gen torus -n 300000 -o " + quoted(dir_ / "big.ply")).exitCode, 0);
  ASSERT_EQ(runIso("convert -q --keep-points " + quoted(dir_ / "big.ply") + " -o " +
                   quoted(dir_ / "big.iso"))
                .exitCode,
            0);
  // Ctrl-C (SIGINT) in the middle of a conversion whose --tmp it had to make, over an old file.
  put(dir_ / "out.iso", "old");
  const fs::path tmp = dir_ / "made" / "tmp";
  pid_t pid = startIso({"convert", "-f", "--progress", "json", "--tmp", tmp.string(),
                        (dir_ / "big.ply").string(), "-o", (dir_ / "out.iso").string()},
                       dir_ / "err");
  // The octree stage runs past the points' files: the temporary directory holds them then.
  ASSERT_TRUE(waitUntil(pid, [&] {
    return fs::exists(dir_ / "err") &&
           test::slurp(dir_ / "err").find("\"stage\":\"octree\"") != std::string::npos;
  })) << "the conversion ended before it could be interrupted";
  EXPECT_TRUE(hasEntryStartingWith(tmp, ".iso-spill."));
  kill(pid, SIGINT);
  int status = 0;
  waitpid(pid, &status, 0);
  // Ended by the signal: a shell reports 128 + 2 = 130, and a script running it stops.
  ASSERT_TRUE(WIFSIGNALED(status)) << status;
  EXPECT_EQ(WTERMSIG(status), SIGINT);
  std::string err = test::slurp(dir_ / "err");
  std::smatch stage;
  const std::string line = lastLine(err);
  ASSERT_TRUE(std::regex_match(
      line, stage,
      std::regex("iso convert: interrupted in the (.+) stage; (.+) keeps what it held, temporary "
                 "files removed, with the directory (.+) made for them")))
      << err;
  EXPECT_NE(err.find("\"stage\":\"" + stage[1].str() + "\""), std::string::npos) << line;
  EXPECT_EQ(stage[2].str(), (dir_ / "out.iso").string());
  EXPECT_EQ(stage[3].str(), (dir_ / "made").string());
  EXPECT_EQ(test::slurp(dir_ / "out.iso"), "old");
  EXPECT_FALSE(fs::exists(dir_ / "made"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());

  // Ctrl-C while an export writes its files: none of them, and an old one as it was.
  put(dir_ / "m.ply", "old mesh");
  std::vector<std::string> exportAll = {"export",
                                        "-f",
                                        (dir_ / "big.iso").string(),
                                        "--points",
                                        (dir_ / "p.ply").string(),
                                        "--mesh",
                                        (dir_ / "m.ply").string()};
  if (ISO_WITH_OPENVDB) exportAll.insert(exportAll.end(), {"--vdb", (dir_ / "v.vdb").string()});
  pid = startIso(exportAll, dir_ / "err");
  ASSERT_TRUE(waitUntil(pid, [&] { return hasEntryStartingWith(dir_.path(), ".p.ply."); }));
  kill(pid, SIGINT);
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << status;
  EXPECT_EQ(WTERMSIG(status), SIGINT);
  err = test::slurp(dir_ / "err");
  EXPECT_TRUE(std::regex_match(
      lastLine(err), std::regex("iso export: interrupted while (writing the (points|mesh|level "
                                "set)|reading the surface of .+); nothing was written, "
                                "temporary files removed")))
      << err;
  EXPECT_EQ(test::slurp(dir_ / "m.ply"), "old mesh");
  EXPECT_FALSE(fs::exists(dir_ / "p.ply"));
  EXPECT_FALSE(fs::exists(dir_ / "v.vdb"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());
}

TEST_F(CliPipeline, aShellSeesStatus143WhenAConversionIsKilledAndNoneWhenItIgnoresHangUps) {
  ASSERT_EQ(runIso("gen torus -n 300000 -o " + quoted(dir_ / "big.ply")).exitCode, 0);
  // sh starts the conversion in the background and reports its status as shells do.
  const std::string script = std::string(ISO_BINARY) + " convert " + quoted(dir_ / "big.ply") +
                             " -o " + quoted(dir_ / "out.iso") + " 2>" + quoted(dir_ / "err") +
                             " & echo $! >" + quoted(dir_ / "pid") + "; wait $!; echo $? >" +
                             quoted(dir_ / "status");
  const pid_t shell = fork();
  if (shell == 0) {
    execl("/bin/sh", "sh", "-c", script.c_str(), nullptr);
    _exit(127);
  }
  pid_t iso = 0;
  ASSERT_TRUE(waitUntil(shell, [&] {
    const std::string text = fs::exists(dir_ / "pid") ? test::slurp(dir_ / "pid") : "";
    if (!text.ends_with('\n')) return false;
    iso = pid_t(std::stol(text));
    return hasEntryStartingWith(dir_.path(), ".iso-spill.");  // reading into its spill files
  }));
  kill(iso, SIGTERM);
  waitpid(shell, nullptr, 0);
  EXPECT_EQ(test::slurp(dir_ / "status"), "143\n");
  const std::string err = test::slurp(dir_ / "err");
  EXPECT_TRUE(lastLine(err).starts_with("iso convert: interrupted ")) << err;
  EXPECT_TRUE(lastLine(err).ends_with("; nothing was written, temporary files removed")) << err;
  EXPECT_FALSE(fs::exists(dir_ / "out.iso"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());

  // Started ignoring SIGHUP (nohup): a closed terminal does not stop it.
  const pid_t pid =
      startIso({"convert", (dir_ / "big.ply").string(), "-o", (dir_ / "out.iso").string()},
               dir_ / "err", SIGHUP);
  ASSERT_TRUE(waitUntil(pid, [&] { return hasEntryStartingWith(dir_.path(), ".iso-spill."); }));
  kill(pid, SIGHUP);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status)) << status;
  EXPECT_EQ(WEXITSTATUS(status), 0) << test::slurp(dir_ / "err");
  EXPECT_EQ(runIso("verify " + quoted(dir_ / "out.iso")).exitCode, 0);
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

// --keep-scalar: a LAS scan's intensity, classification and GPS time come back with each kept
// point from `iso export --points` (intensity and classification exactly, the GPS time within
// half its step), in core and out of core alike; `density` is the scan's point density.
TEST_F(CliPipeline, keptScalarsComeBackWithTheirPoints) {
  const PointCloud sphere = readPointFile(dir_ / "sphere.ply");
  LasScan scan = lasOf(sphere, 2, 1, [](size_t) { return std::array<uint16_t, 3>{}; });
  std::map<std::tuple<int64_t, int64_t, int64_t>, std::array<double, 3>> truth;
  for (size_t i = 0; i < scan.spec.points.size(); ++i) {
    test::LasPoint& p = scan.spec.points[i];
    p.fields = true;
    p.intensity = uint16_t((i * 7919) % 65536);
    p.returns = uint8_t(1 + i % 3);
    p.classification = uint8_t(i % 19);
    p.gpsTime = 4.0e8 + 0.00037 * double(i);
    truth[{p.x, p.y, p.z}] = {double(p.intensity), double(p.classification), p.gpsTime};
  }
  test::writeFile(dir_ / "s.las", test::makeLas(scan.spec).bytes());
  const std::array<std::string, 3> names = {"intensity", "classification", "gps_time"};
  for (size_t k = 0; k < names.size(); ++k) {
    SCOPED_TRACE(names[k]);
    for (const std::string memory : {"", " --chunk-points 6990"}) {
      const auto iso = dir_ / ("s-" + names[k] + (memory.empty() ? "" : "-small") + ".iso");
      auto run = runIso("convert -q --keep-points --point-bits 30 --keep-scalar " + names[k] +
                        memory + " " + quoted(dir_ / "s.las") + " -o " + quoted(iso));
      ASSERT_EQ(run.exitCode, 0) << run.err;
    }
    const auto iso = dir_ / ("s-" + names[k] + ".iso");
    EXPECT_EQ(test::readFile(iso), test::readFile(dir_ / ("s-" + names[k] + "-small.iso")));
    ASSERT_EQ(runIso("export -f " + quoted(iso) + " --points " + quoted(dir_ / "k.ply")).exitCode,
              0);
    const PointCloud kept = readPointFile(dir_ / "k.ply", {.columns = "", .keepExtras = true});
    ASSERT_EQ(kept.extraNames, std::vector<std::string>{names[k]});
    ASSERT_EQ(kept.size(), sphere.size());
    const double span = 0.00037 * double(sphere.size() - 1);
    size_t matched = 0;
    double worst = 0.0;
    for (size_t i = 0; i < kept.size(); ++i) {
      // Positions to 2^-30 of the frame: they round back to the LAS's integers.
      const glm::dvec3 q = (kept.positions[i] - scan.spec.offset) / scan.spec.scale;
      const auto at = truth.find({std::llround(q.x), std::llround(q.y), std::llround(q.z)});
      if (at == truth.end()) continue;
      ++matched;
      worst = std::max(worst, std::abs(kept.extras[i] - at->second[k]));
    }
    EXPECT_GT(matched, kept.size() * 99 / 100);
    if (k < 2)
      EXPECT_EQ(worst, 0.0);
    else
      EXPECT_LE(worst, span / 65534 / 2 * 1.0001);
  }
  // The density of a sphere of N points and radius 10: N / (4π 10²) points per square unit.
  auto run = runIso("convert -q --keep-points --keep-scalar density " + quoted(dir_ / "s.las") +
                    " -o " + quoted(dir_ / "d.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  ASSERT_EQ(runIso("export " + quoted(dir_ / "d.iso") + " --points " + quoted(dir_ / "d.ply"))
                .exitCode,
            0);
  PointCloud density = readPointFile(dir_ / "d.ply", {.columns = "", .keepExtras = true});
  ASSERT_EQ(density.extraNames, std::vector<std::string>{"density"});
  std::vector<double> values = density.extras;
  std::nth_element(values.begin(), values.begin() + ptrdiff_t(values.size() / 2), values.end());
  const double analytic = double(sphere.size()) / (4.0 * std::numbers::pi * 100.0);
  EXPECT_NEAR(values[values.size() / 2], analytic, 0.2 * analytic);
}

// --volume-points: a volume's samples and their values are stored beside the surface, exported by
// `iso export --volume-points`, and do not change the surface.
TEST_F(CliPipeline, volumePointsAreKeptBesideTheSurfaceWithTheirValues) {
  std::string text;
  std::vector<std::array<double, 4>> samples;
  for (int i = 0; i < 5000; ++i) {
    const double u = double((i * 37) % 101) / 101.0, v = double((i * 53) % 97) / 97.0,
                 w = double(i) / 5000.0;
    const std::array<double, 4> s = {1.6 * u - 0.8, 1.6 * v - 0.8, 1.6 * w - 0.8,
                                     std::exp(-3.0 * (u * u + v * v + w * w)) * 1000.0 + i % 7};
    samples.push_back(s);
    text += fmt::format("{} {} {} {}\n", s[0], s[1], s[2], s[3]);
  }
  test::writeText(dir_ / "values.xyz", text);
  const std::string sphere = quoted(dir_ / "sphere.ply");
  auto run = runIso("convert -q " + sphere + " -o " + quoted(dir_ / "plain.iso"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  run = runIso("convert -q " + sphere + " -o " + quoted(dir_ / "v.iso") + " --volume-points " +
               quoted(dir_ / "values.xyz") + " --volume-columns x,y,z,value --keep-scalar value");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const Reader plain = Reader::open(dir_ / "plain.iso"), withVolume = Reader::open(dir_ / "v.iso");
  size_t surface = 0;
  for (const ChunkInfo& c : withVolume.chunks()) {
    if (c.kind != kSurfaceKind) continue;
    ASSERT_LT(c.id, plain.chunks().size());
    EXPECT_EQ(plain.payload(c.id).bytes().size(), withVolume.payload(c.id).bytes().size());
    EXPECT_TRUE(std::ranges::equal(plain.payload(c.id).bytes(), withVolume.payload(c.id).bytes()));
    ++surface;
  }
  EXPECT_GT(surface, 0u);
  run = runIso("export " + quoted(dir_ / "v.iso") + " --volume-points " + quoted(dir_ / "v.ply"));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("5,000 volume points"), std::string::npos) << run.out;
  const PointCloud back = readPointFile(dir_ / "v.ply", {.columns = "", .keepExtras = true});
  ASSERT_EQ(back.extraNames, std::vector<std::string>{"value"});
  ASSERT_EQ(back.size(), samples.size());
  // Each exported sample is an input sample (positions to 2^-24 of the frame), its value within
  // half a step of the values' span / 65534.
  double lo = 1e300, hi = -1e300;
  for (const auto& s : samples) {
    lo = std::min(lo, s[3]);
    hi = std::max(hi, s[3]);
  }
  size_t far = 0;
  double worst = 0.0;
  for (size_t i = 0; i < back.size(); ++i) {
    double best = 1e300;
    const std::array<double, 4>* nearest = nullptr;
    for (const auto& s : samples) {
      const double d = glm::length(back.positions[i] - glm::dvec3(s[0], s[1], s[2]));
      if (d < best) {
        best = d;
        nearest = &s;
      }
    }
    far += best > 1e-5 ? 1 : 0;
    worst = std::max(worst, std::abs(back.extras[i] - (*nearest)[3]));
  }
  EXPECT_EQ(far, 0u);
  EXPECT_LE(worst, (hi - lo) / 65534 / 2 * 1.0001);
  // The surface's own export has no volume points; a file without them says so.
  run = runIso("export " + quoted(dir_ / "plain.iso") + " --volume-points " +
               quoted(dir_ / "none.ply"));
  EXPECT_NE(run.exitCode, 0);
  EXPECT_NE(run.err.find("keeps no volume points"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "none.ply"));
}

TEST_F(CliPipeline, impossibleScalarAndVolumeOptionsAreRefusedBeforeAnyWork) {
  const std::string sphere = quoted(dir_ / "sphere.ply"), out = quoted(dir_ / "o.iso");
  test::writeText(dir_ / "values.xyz", "0 0 0 1\n");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--keep-scalar intensity", "--keep-scalar keeps a value with the kept points"},
      {"--keep-points --keep-scalar intensity", "sphere.ply: has no scalar 'intensity'"},
      {"--volume-points " + quoted(dir_ / "values.xyz"), "--volume-points needs --keep-scalar"},
      {"--volume-points " + quoted(dir_ / "values.xyz") + " --keep-scalar value",
       "values.xyz: has no scalar 'value'"},
      {"--volume-points " + quoted(dir_ / "values.xyz") + " --keep-scalar density",
       "--keep-scalar density is the scan's point density"},
      {"--keep-points --keep-scalar " + std::string(33, 'n'), "a name of at most 32 bytes"},
      {"--volume-points " + sphere + " --keep-scalar x", "is also a scan input"},
  };
  for (const auto& [options, reason] : cases) {
    SCOPED_TRACE(options);
    const auto run = runIso("convert -q " + options + " " + sphere + " -o " + out);
    EXPECT_NE(run.exitCode, 0);
    EXPECT_NE(run.err.find(reason), std::string::npos) << run.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / "o.iso"));
  }
}

// kill -9 at several moments of a conversion run with --resume; run again with --resume, it goes on
// from the last checkpoint it finds whole and writes the same bytes as a run that went through.
TEST_F(CliPipeline, aKilledResumableConversionGoesOnFromItsLastCheckpointToTheSameBytes) {
  const fs::path in = dir_ / "torus.ply", out = dir_ / "out.iso";
  const fs::path state = dir_ / ".out.iso.resume";
  ASSERT_EQ(runIso("gen torus -n 200000 -o " + quoted(in)).exitCode, 0);
  ASSERT_EQ(runIso("convert -q " + quoted(in) + " -o " + quoted(dir_ / "ref.iso")).exitCode, 0);
  const std::string reference = test::slurp(dir_ / "ref.iso");
  const auto killIn = [&](const std::string& stage, std::vector<std::string> more = {}) {
    fs::remove(dir_ / "err");  // not read before the new run makes it
    std::vector<std::string> args = {"convert", "--resume", "-f", "--progress", "json"};
    args.insert(args.end(), more.begin(), more.end());
    args.insert(args.end(), {in.string(), "-o", out.string()});
    const pid_t pid = startIso(args, dir_ / "err");
    const bool caught = waitUntil(pid, [&] {
      return fs::exists(dir_ / "err") &&
             test::slurp(dir_ / "err").find("\"stage\":\"" + stage + "\"") != std::string::npos;
    });
    if (caught) kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
    return caught;
  };
  const auto resume = [&](const std::string& more = "") {
    const auto run =
        runIso("convert --resume -f --json " + more + quoted(in) + " -o " + quoted(out));
    EXPECT_EQ(run.exitCode, 0) << run.err;
    EXPECT_FALSE(fs::exists(state)) << "the state outlived the run it was kept for";
    return std::pair{nlohmann::json::parse(run.out, nullptr, false), run.err};
  };
  // The stage killed in, and the checkpoint the next run goes on from ("" for none).
  for (const auto& [stage, from] :
       std::vector<std::pair<std::string, std::string>>{{"points", ""},
                                                        {"octree", "points"},
                                                        {"corners", "points"},
                                                        {"lod", "corners"},
                                                        {"write", "corners"}}) {
    SCOPED_TRACE(stage);
    ASSERT_TRUE(killIn(stage)) << "the conversion ended before the " << stage << " stage";
    EXPECT_TRUE(fs::is_directory(state));
    const auto [report, err] = resume();
    if (from.empty())
      EXPECT_FALSE(report.contains("resumed")) << report.dump();
    else
      EXPECT_EQ(report["resumed"]["from"], from) << report.dump();
    EXPECT_TRUE(test::slurp(out) == reference);
  }

  // A damaged checkpoint is removed and never used: the run goes on from the one before.
  ASSERT_TRUE(killIn("lod"));
  {
    std::fstream f(state / "corners.checkpoint", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(fs::file_size(state / "corners.checkpoint") / 2));
    f.put('\x5a');
  }
  auto [report, err] = resume();
  EXPECT_EQ(report["resumed"]["from"], "points") << report.dump();
  EXPECT_NE(err.find("corners.checkpoint: section corner"), std::string::npos) << err;
  EXPECT_TRUE(test::slurp(out) == reference);

  // Converted straight with `more` (options, each followed by a space) into `straight`, then
  // killed once `checkpoint` is in the state (`notYet`, the stage's checkpoint, not) and resumed:
  // the report of the resumed run, whose file must be the same bytes.
  const auto killAfter = [&](const std::string& more, const std::string& checkpoint,
                             const std::string& notYet, const fs::path& straight) {
    EXPECT_EQ(runIso("convert -q " + more + quoted(in) + " -o " + quoted(straight)).exitCode, 0);
    std::vector<std::string> args = {"convert", "--resume", "-f"};
    for (size_t at = 0, next; (next = more.find(' ', at)) != std::string::npos; at = next + 1)
      args.push_back(more.substr(at, next - at));
    args.insert(args.end(), {in.string(), "-o", out.string()});
    const pid_t pid = startIso(args, dir_ / "err");
    EXPECT_TRUE(waitUntil(pid, [&] { return fs::exists(state / checkpoint); }));
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
    EXPECT_FALSE(fs::exists(state / notYet));
    auto resumed = resume(more);
    EXPECT_TRUE(test::slurp(out) == test::slurp(straight));
    return resumed.first;
  };

  // Killed in the point stages of many chunks, it keeps the chunks it finished.
  report = killAfter("--chunk-points 34952 --orient-block-points 20000 ", "chunk-0-2",
                     "points.checkpoint", dir_ / "chunked.iso");
  EXPECT_GE(report["out_of_core"]["chunks_resumed"].get<int>(), 2) << report.dump();
  EXPECT_LT(report["out_of_core"]["chunks_resumed"], report["out_of_core"]["chunks"]);
  // A chunk's checkpoint damaged past its points (found once they were read into the results):
  // the chunk runs again, the chunks after it are kept, and the bytes are the same.
  {
    const pid_t pid = startIso({"convert", "--resume", "-f", "--chunk-points", "34952",
                                "--orient-block-points", "20000", in.string(), "-o", out.string()},
                               dir_ / "err");
    EXPECT_TRUE(waitUntil(pid, [&] { return fs::exists(state / "chunk-0-2"); }));
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
  int finished = 0;
  for (const fs::directory_entry& e : fs::directory_iterator(state))
    finished += e.path().filename().string().starts_with("chunk-0-") ? 1 : 0;
  {
    const fs::path chunk = state / "chunk-0-1";
    std::fstream f(chunk, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(fs::file_size(chunk) * 95 / 100));
    const char was = char(f.peek());
    f.put(char(was ^ 0x5a));
  }
  std::tie(report, err) = resume("--chunk-points 34952 --orient-block-points 20000 ");
  EXPECT_EQ(report["out_of_core"]["chunks_resumed"].get<int>(), finished - 1) << report.dump();
  EXPECT_NE(err.find("chunk-0-1: section"), std::string::npos) << err;
  EXPECT_TRUE(test::slurp(out) == test::slurp(dir_ / "chunked.iso"));

  // Killed in the chunk jobs of the octree stages, it keeps the jobs it finished.
  report = killAfter("--octree-chunk-points 20000 ", "octree-chunk-2", "corners.checkpoint",
                     dir_ / "octree-chunks.iso");
  EXPECT_GE(report["resumed"]["octree_chunks"].get<int>(), 2) << report.dump();
  EXPECT_LT(report["resumed"]["octree_chunks"], report["octree_chunks"]["chunks"]);
  // Killed after its jobs, a chunked run goes on from all of them: its jobs are its checkpoints.
  ASSERT_TRUE(killIn("lod", {"--octree-chunk-points", "20000"}));
  EXPECT_FALSE(fs::exists(state / "corners.checkpoint"));
  report = resume("--octree-chunk-points 20000 ").first;
  EXPECT_EQ(report["resumed"]["octree_chunks"], report["octree_chunks"]["chunks"]) << report.dump();
  EXPECT_TRUE(test::slurp(out) == test::slurp(dir_ / "octree-chunks.iso"));

  // The state of a run with other options is not resumed from.
  ASSERT_TRUE(killIn("lod"));
  std::tie(report, err) = resume("--smoothing 1.5 ");
  EXPECT_FALSE(report.contains("resumed")) << report.dump();
  EXPECT_NE(err.find("was of another conversion"), std::string::npos) << err;
  EXPECT_FALSE(test::slurp(out) == reference);
}

// A distributed run on MPI (Debian's OpenMPI): two ranks share the point stages' chunks and write
// the same bytes as one process, strays that change the frame included; an error ends both.
// Real scans as chunk jobs of the octree stages (forced small: 8–18 chunks of these scans) are as
// accurate and as closed to the viewer as in one run (specs/pipeline.md §15, item 6).
TEST_F(CliPipeline, realScansAsChunkJobsAreAsAccurateAndAsClosedAsOneRun) {
  const fs::path data = ISO_SHARED_DATA_DIR;
  size_t scans = 0;
  for (const char* name : {"table_scene_lms400.pcd", "lone_star_tls_utm.las", "lion_rgb.las"}) {
    if (!fs::exists(data / name)) continue;
    SCOPED_TRACE(name);
    ++scans;
    const auto convert = [&](const std::string& more) {
      const auto run = runIso("convert -q -f --json " + more + quoted(data / name) + " -o " +
                              quoted(dir_ / "scan.iso"));
      EXPECT_EQ(run.exitCode, 0) << run.err;
      return nlohmann::json::parse(run.out, nullptr, false);
    };
    const nlohmann::json one = convert("");
    const nlohmann::json jobs = convert("--octree-chunk-points 20000 ");
    ASSERT_FALSE(one.contains("octree_chunks"));
    EXPECT_GE(jobs["octree_chunks"]["chunks"].get<int>(), 8) << jobs["octree_chunks"].dump();
    for (const char* key : {"rms_over_spacing", "max_over_spacing"})
      EXPECT_LE(jobs["accuracy"][key].get<double>(), 1.02 * one["accuracy"][key].get<double>())
          << key;
    for (const char* key : {"seen_through_fraction", "worst_view_fraction"})
      EXPECT_LE(jobs["visibility"][key].get<double>(),
                one["visibility"][key].get<double>() + 1e-4)
          << key;
    const double leaves = one["octree"]["leaves"].get<double>();
    EXPECT_NEAR(jobs["octree"]["leaves"].get<double>(), leaves, 0.01 * leaves);
  }
  if (scans == 0) GTEST_SKIP() << "no " << data << " (the shared data folder)";
}

TEST_F(CliPipeline, twoMpiRanksWriteTheSameBytesAsOneProcess) {
  if (test::runCommand("command -v mpirun").exitCode != 0)
    GTEST_SKIP() << "no mpirun (tools/run setup)";
  const fs::path in = dir_ / "torus.ply", far = dir_ / "far.xyz";
  ASSERT_EQ(runIso("gen torus -n 200000 -o " + quoted(in)).exitCode, 0);
  put(far, "5 5 5\n5.01 5 5\n");  // strays that held the bounds: every chunk runs again
  // Chunks of at most 34,952 points and orientation blocks that fit them.
  const std::string options = " --chunk-points 34952 --orient-block-points 20000 -f --json " +
                              quoted(in) + " " + quoted(far) + " -o ";
  const auto one = runIso("convert" + options + quoted(dir_ / "one.iso"));
  ASSERT_EQ(one.exitCode, 0) << one.err;
  // As root (a container, CI) OpenMPI asks for these; --oversubscribe: fewer cores than ranks.
  const std::string mpirun =
      "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 "
      "OMPI_MCA_rmaps_base_oversubscribe=1 "
      "mpirun -np 2 " +
      std::string(ISO_BINARY) + " convert";
  const auto two = test::runCommand(mpirun + options + quoted(dir_ / "two.iso"));
  ASSERT_EQ(two.exitCode, 0) << two.err;
  const nlohmann::json report = nlohmann::json::parse(two.out);
  EXPECT_EQ(report["out_of_core"]["ranks"], 2);
  EXPECT_GT(report["out_of_core"]["chunks"].get<int>(), 4);
  EXPECT_EQ(report["points"]["outliers_removed"], 2);
  // Rank 1 measured what a viewer shows (the same numbers: they are in the file's metadata).
  EXPECT_EQ(report["out_of_core"]["visibility_rank"], 1);
  EXPECT_TRUE(test::slurp(dir_ / "two.iso") == test::slurp(dir_ / "one.iso"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());

  // The octree stages as chunk jobs, shared by the ranks too.
  const std::string jobs = " --octree-chunk-points 20000" + options;
  const auto oneJobs = runIso("convert" + jobs + quoted(dir_ / "one-jobs.iso"));
  ASSERT_EQ(oneJobs.exitCode, 0) << oneJobs.err;
  const auto twoJobs = test::runCommand(mpirun + jobs + quoted(dir_ / "two-jobs.iso"));
  ASSERT_EQ(twoJobs.exitCode, 0) << twoJobs.err;
  const nlohmann::json jobsReport = nlohmann::json::parse(twoJobs.out);
  EXPECT_GT(jobsReport["octree_chunks"]["chunks"].get<int>(), 2);
  bool waited = false;
  for (const nlohmann::json& stage : jobsReport["stages"]) waited |= stage["name"] == "ranks";
  EXPECT_TRUE(waited) << jobsReport["stages"].dump();
  EXPECT_TRUE(test::slurp(dir_ / "two-jobs.iso") == test::slurp(dir_ / "one-jobs.iso"));
  EXPECT_TRUE(temporariesUnder(dir_.path()).empty());

  const auto refused = test::runCommand(mpirun + " --resume" + options + quoted(dir_ / "x.iso"));
  EXPECT_NE(refused.exitCode, 0);
  EXPECT_NE(refused.err.find("cannot be used with 2 ranks"), std::string::npos) << refused.err;
  EXPECT_FALSE(fs::exists(dir_ / "x.iso"));
}

}  // namespace
}  // namespace iso
