// `iso view` as a user runs it: pictures, the window under Xvfb, bad files and bad options.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <unistd.h>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>

#include "iso/reader.h"
#include "pipeline/io/ply.h"
#include "pipeline/io/readers.h"
#include "tests/cli_support.h"
#include "base/image.h"

namespace iso::test {
namespace {

CommandResult iso(const std::string& arguments) { return runIso(arguments); }

// A small converted scan shared by the tests (the bundled kitten, cut into many chunks).
const std::filesystem::path& kittenIso() {
  static TempDir dir;
  static const std::filesystem::path path = [] {
    const auto out = dir / "kitten.iso";
    const CommandResult run =
        iso("convert --quiet --chunk-nodes 400 " +
            quoted(std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz") + " -o " +
            quoted(out));
    EXPECT_EQ(run.exitCode, 0) << run.err;
    return out;
  }();
  return path;
}

// A picture of the expected size that shows something: many colors, and much of it unlike its
// top-left pixel (the sky).
// Returns its pixels.
std::vector<uint32_t> expectPicture(const std::filesystem::path& png, uint32_t width,
                                    uint32_t height) {
  uint32_t w = 0, h = 0;
  auto pixels = readRgba8Image(png, w, h);
  EXPECT_EQ(w, width);
  EXPECT_EQ(h, height);
  const std::set<uint32_t> colors(pixels.begin(), pixels.end());
  size_t unlike = 0;
  for (uint32_t p : pixels) unlike += p != pixels[0];
  EXPECT_GT(colors.size(), 50u);
  EXPECT_GT(double(unlike) / pixels.size(), 0.1);
  return pixels;
}

TEST(CliView, headlessAndCpuWritePicturesOfTheSurface) {
  TempDir dir;
  for (const char* mode : {"--headless", "--cpu"}) {
    SCOPED_TRACE(mode);
    const auto out = dir / (std::string(mode + 2) + ".png");
    const CommandResult run = iso("view " + quoted(kittenIso()) + " " + mode + " --out " +
                                  quoted(out) + " --width 120 --height 90 --spp 2");
    ASSERT_EQ(run.exitCode, 0) << run.err;
    EXPECT_NE(run.out.find(out.string()), std::string::npos) << run.out;
    expectPicture(out, 120, 90);
  }
}

TEST(CliView, benchPrintsItsNumbers) {
  const CommandResult run = iso("view " + quoted(kittenIso()) +
                                " --bench --bench-frames 4 --width 64 --height 64 --vram 64M");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  for (const char* line : {"ms/frame", "max/median", "GPU ms", "GPU idle", "rays/s", "first view",
                           "CPU rays/s", "GPU/CPU", "GPU memory", "chunks", "streamed"})
    EXPECT_NE(run.out.find(line), std::string::npos) << line << "\n" << run.out;
  const CommandResult gpuOnly = iso("view " + quoted(kittenIso()) +
                                    " --bench --bench-frames 2 --width 32 --height 32 "
                                    "--no-cpu-compare --frames-in-flight 3");
  ASSERT_EQ(gpuOnly.exitCode, 0) << gpuOnly.err;
  EXPECT_NE(gpuOnly.out.find("3 in flight"), std::string::npos) << gpuOnly.out;
  EXPECT_EQ(gpuOnly.out.find("CPU rays/s"), std::string::npos) << gpuOnly.out;
}

// The bench traces its first view on the GPU (converged) and on the CPU with the whole file,
// with the same parameters and frame number (the jitter of 2 samples a pixel hashes it): the same
// rays of each kind. Camera rays are equal by construction; the others follow the hits, which
// agree but for float rounding (the kitten: equal; the lion: 1 shadow ray in 8,053 differs).
TEST(CliView, benchTracesTheSameRaysOfEachKindOnTheGpuAndTheCpu) {
  const uint32_t w = 160, h = 120, frames = 3;
  const CommandResult run =
      iso("view " + quoted(kittenIso()) + " --bench --json --bench-frames " +
          std::to_string(frames) + " --width " + std::to_string(w) + " --height " +
          std::to_string(h) + " --spp 2 --reflectivity 0.3 --bounces 1 --lod-pixels 0.5");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto j = nlohmann::json::parse(run.out);
  ASSERT_TRUE(j["first_view"]["converged"].get<bool>()) << run.out;
  const auto& gpu = j["first_view"]["rays"];
  const auto& cpu = j["cpu"]["rays"];
  EXPECT_EQ(gpu["primary"].get<uint64_t>(), 2 * uint64_t(w) * h);
  EXPECT_EQ(cpu["primary"].get<uint64_t>(), 2 * uint64_t(w) * h);
  EXPECT_GT(gpu["shadow"].get<uint64_t>(), uint64_t(w) * h / 20) << gpu;
  EXPECT_GT(gpu["secondary"].get<uint64_t>(), uint64_t(w) * h / 20) << gpu;
  for (const char* kind : {"shadow", "secondary"})
    EXPECT_NEAR(gpu[kind].get<double>(), cpu[kind].get<double>(), 1e-3 * cpu[kind].get<double>())
        << kind;
  // The orbit's other frames are all timed, and the rates add up.
  ASSERT_EQ(j["orbit_frames"].size(), frames - 1);
  const auto& rates = j["rays_per_second"];
  EXPECT_NEAR(rates["all"].get<double>(),
              rates["primary"].get<double>() + rates["shadow"].get<double>() +
                  rates["secondary"].get<double>(),
              1e-6 * rates["all"].get<double>());
  EXPECT_GT(j["cpu"]["gpu_over_cpu"]["all"].get<double>(), 0.0);
}

// Frames without refraction run as a wavefront on a CPU device (lavapipe, llvmpipe) and as one
// kernel on a GPU, the faster on each (specs/viewer.md, "On an NVIDIA H200"); --one-kernel and
// --wavefront choose.
TEST(CliView, theKernelsFollowTheDeviceUnlessNamed) {
  auto twoPasses = [](const std::string& options) {
    const CommandResult run = iso("view " + quoted(kittenIso()) +
                                  " --bench --json --bench-frames 2 --width 64 --height 48 "
                                  "--no-cpu-compare " + options);
    EXPECT_EQ(run.exitCode, 0) << run.err;
    const auto j = nlohmann::json::parse(run.out);
    return std::pair(j["two_passes"].get<bool>(), j["device"].get<std::string>());
  };
  const auto [byDefault, device] = twoPasses("");
  EXPECT_EQ(byDefault, device.find("llvmpipe") != std::string::npos) << device;
  EXPECT_FALSE(twoPasses("--one-kernel").first);
  EXPECT_TRUE(twoPasses("--wavefront").first);
}

// `xvfb-run` on a virtual screen of the given size. `-a` alone picks the first free display
// number, and two tests that start at once can both pick it (one of them then finds no display):
// each test process starts its search at its own number (-n before -a: xvfb-run searches when it
// reads -a).
std::string xvfbRun(const std::string& screen) {
  return "xvfb-run -n " + std::to_string(100 + getpid() % 4000) + " -a -s '-screen 0 " + screen +
         "' ";
}

// Runs the window session tests/viewer/SCRIPT on FILE under xvfb-run in DIR (its out.txt and
// err.txt there); whether it ended well (else a failure with what it said).
bool windowSession(const std::string& script, const std::filesystem::path& file,
                   const std::filesystem::path& dir, const std::string& more = "") {
  const std::string command =
      xvfbRun("800x600x24") +
      quoted(std::filesystem::path(ISO_TEST_DATA_DIR) / ".." / "viewer" / script) + " " +
      std::string(ISO_BINARY) + " " + quoted(file) + " " + quoted(dir) + " " + more + " 2>" +
      quoted(dir / "session.txt");
  const int status = std::system(command.c_str());
  const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  EXPECT_TRUE(ok) << slurp(dir / "session.txt") << slurp(dir / "err.txt");
  return ok;
}

// Window sessions need xvfb-run and xdotool.
#define SKIP_WITHOUT_XDOTOOL()                                                                \
  if (std::system("command -v xvfb-run >/dev/null 2>&1 && command -v xdotool >/dev/null 2>&1")) \
  GTEST_SKIP() << "xvfb-run or xdotool is not installed (tools/run setup installs them)"

TEST(CliView, aWindowOpensUnderXvfbAndItsScreenshotIsNotBlank) {
  if (std::system("command -v xvfb-run >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "xvfb-run is not installed (tools/run setup installs it)";
  TempDir dir;
  const auto shot = dir / "shot.png";
  const std::string command = xvfbRun("640x480x24") + std::string(ISO_BINARY) + " view " +
                              quoted(kittenIso()) + " --frames 12 --screenshot " + quoted(shot) +
                              " --width 160 --height 120 >" + quoted(dir / "out") + " 2>" +
                              quoted(dir / "err");
  const int status = std::system(command.c_str());
  ASSERT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 0) << slurp(dir / "err");
  EXPECT_NE(slurp(dir / "out").find("chunks"), std::string::npos) << slurp(dir / "out");
  expectPicture(shot, 160, 120);
}

TEST(CliView, theWindowResizesTakesScreenshotsOrbitsAndReloadsItsScene) {
  SKIP_WITHOUT_XDOTOOL();
  TempDir dir;
  ASSERT_TRUE(windowSession("window_session.sh", kittenIso(), dir.path()));
  EXPECT_NE(slurp(dir / "out.txt").find("saved"), std::string::npos) << slurp(dir / "out.txt");
  // Every picture is at the new size; the orbit turned the view by the time the second was taken
  // (with the button still down) and for good.
  expectPicture(dir / "iso-screenshot-1.png", 480, 260);
  expectPicture(dir / "iso-screenshot-2.png", 480, 260);
  expectPicture(dir / "final.png", 480, 260);
  uint32_t w = 0, h = 0;
  const auto before = readRgba8Image(dir / "iso-screenshot-1.png", w, h);
  const auto during = readRgba8Image(dir / "iso-screenshot-2.png", w, h);
  const auto after = readRgba8Image(dir / "final.png", w, h);
  const auto changedFromBefore = [&](const std::vector<uint32_t>& picture) {
    size_t changed = 0;
    for (size_t i = 0; i < before.size(); ++i) changed += before[i] != picture[i];
    return changed;
  };
  EXPECT_GT(changedFromBefore(during), before.size() / 20);
  EXPECT_GT(changedFromBefore(after), before.size() / 20);
  // The scene file changed under the window: the surface turned red, and the window said so.
  EXPECT_NE(slurp(dir / "out.txt").find("reloaded"), std::string::npos) << slurp(dir / "out.txt");
  const auto redder = [](const std::vector<uint32_t>& picture) {
    size_t n = 0;
    for (uint32_t p : picture) n += int(p & 0xFF) > int(p >> 8 & 0xFF) + 40;
    return n;
  };
  EXPECT_EQ(redder(before), 0u);
  EXPECT_GT(redder(after), after.size() / 20);
}

// The window starts at the default view, as --headless draws it at the same size, and Home
// brings it back there after an orbit.
TEST(CliView, theWindowStartsAtTheDefaultViewAndHomeGoesBackToIt) {
  SKIP_WITHOUT_XDOTOOL();
  TempDir dir;
  ASSERT_TRUE(windowSession("home_window_session.sh", kittenIso(), dir.path()));
  const auto headless = dir / "headless.png";
  const CommandResult run = iso("view " + quoted(kittenIso()) +
                                " --headless --width 300 --height 200 --out " + quoted(headless));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  uint32_t w = 0, h = 0;
  const auto start = readRgba8Image(dir / "iso-screenshot-1.png", w, h);
  ASSERT_EQ(w * h, 300u * 200u);
  const auto orbited = readRgba8Image(dir / "iso-screenshot-2.png", w, h);
  const auto home = readRgba8Image(dir / "final.png", w, h);
  const auto drawn = readRgba8Image(headless, w, h);
  // Pixels whose channels differ by more than 8 of 255.
  const auto differing = [](const std::vector<uint32_t>& a, const std::vector<uint32_t>& b) {
    size_t n = 0;
    for (size_t i = 0; i < a.size(); ++i)
      for (int k = 0; k < 3; ++k)
        if (std::abs(int(a[i] >> 8 * k & 255) - int(b[i] >> 8 * k & 255)) > 8) {
          ++n;
          break;
        }
    return n;
  };
  EXPECT_GT(differing(start, orbited), start.size() / 20);
  EXPECT_LT(differing(start, home), start.size() / 100);
  EXPECT_LT(differing(start, drawn), start.size() / 100);
}

TEST(CliView, badFilesGiveAClearErrorAndNoPicture) {
  TempDir dir;
  const std::vector<std::byte> good = readFile(kittenIso());
  const auto out = dir / "picture.png";
  // Truncated.
  std::vector<std::byte> cut(good.begin(), good.begin() + good.size() / 2);
  writeFile(dir / "cut.iso", cut);
  CommandResult run = iso("view " + quoted(dir / "cut.iso") + " --headless --out " + quoted(out));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find((dir / "cut.iso").string()), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(out));
  // A byte flipped in the last chunk's payload: found when that chunk streams in, before it is
  // drawn; an older picture at --out stays as it was.
  std::vector<std::byte> flipped = good;
  {
    const auto reader = Reader::fromMemory(good, "kitten");
    const ChunkInfo& last = reader.chunks().back();
    flipped[last.offset + last.storedSize / 2] ^= std::byte{0x40};
  }
  writeFile(dir / "flipped.iso", flipped);
  std::ofstream(out) << "old picture";
  for (const char* mode : {"--headless", "--cpu"}) {
    run = iso("view " + quoted(dir / "flipped.iso") + " " + mode + " --out " + quoted(out) +
              " --width 200 --height 200 --lod-pixels 0");
    EXPECT_EQ(run.exitCode, 1) << mode;
    EXPECT_NE(run.err.find((dir / "flipped.iso").string()), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("checksum mismatch"), std::string::npos) << run.err;
    EXPECT_EQ(slurp(out), "old picture");
  }
  // Not an .iso file at all.
  std::ofstream(dir / "text.iso") << "hello";
  run = iso("view " + quoted(dir / "text.iso") + " --headless --out " + quoted(out));
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("text.iso"), std::string::npos) << run.err;
}

// Raw scans draw as image-space points without a conversion: on the CPU reference and on the
// GPU alike, several files at once, timed; damaged files are the reader's errors.
TEST(CliView, rawScansDrawAsImageSpacePoints) {
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  const std::string kitten = quoted(data / "kitten_normals.xyz");
  const std::string size = " --width 200 --height 160";
  const auto cpu = dir / "cpu.png", gpu = dir / "gpu.png";
  CommandResult run = iso("view " + kitten + " --cpu --out " + quoted(cpu) + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("5210 points from 1 file"), std::string::npos) << run.out;
  expectPicture(cpu, 200, 160);
  run = iso("view " + kitten + " --draw image --headless --out " + quoted(gpu) + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  uint32_t w = 0, h = 0;
  const auto a = readRgba8Image(cpu, w, h), b = readRgba8Image(gpu, w, h);
  ASSERT_EQ(a.size(), b.size());
  size_t differ = 0;
  for (size_t i = 0; i < a.size(); ++i)
    for (int k = 0; k < 3; ++k)
      if (std::abs(int((a[i] >> (8 * k)) & 255) - int((b[i] >> (8 * k)) & 255)) > 8) {
        ++differ;
        break;
      }
  EXPECT_LT(double(differ) / double(a.size()), 0.005) << differ << " pixels differ";
  // Two files, one a LAZ, each with its opacity, in three layers; timed.
  const std::string both = kitten + " " + quoted(data / "laz" / "las12-f2-variable.laz");
  run = iso("view " + both + " --bench --json --bench-frames 2 --layers 3 --opacity 1,0.5" + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["files"].size(), 2u);
  EXPECT_EQ(j["layers"].get<int>(), 3);
  EXPECT_GT(j["frames_per_second"].get<double>(), 0.0);
  // Each file's points once: the two files' counts, each read alone.
  run = iso("view " + quoted(data / "laz" / "las12-f2-variable.laz") +
            " --bench --json --bench-frames 2" + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_EQ(j["points"].get<uint64_t>(),
            5210u + nlohmann::json::parse(run.out)["points"].get<uint64_t>());
  // Impossible options.
  EXPECT_EQ(iso("view " + both + " --cpu --out x.png --opacity 0.5,0.5,0.5").exitCode, 2);
  EXPECT_EQ(iso("view " + both + " --cpu --out x.png --opacity 1,0").exitCode, 2);
  run = iso("view " + quoted(kittenIso()) + " --draw image --cpu --out x.png");
  EXPECT_EQ(run.exitCode, 1);
  EXPECT_NE(run.err.find("keeps no points"), std::string::npos) << run.err;
  EXPECT_EQ(iso("view " + quoted(kittenIso()) + " " + kitten + " --cpu --out x.png").exitCode, 2);
  // A picture over any of the inputs is refused, the input untouched (a text scan named like a
  // picture reads by its content).
  const auto second = dir / "second.ppm";
  std::filesystem::copy_file(data / "kitten_normals.xyz", second);
  const std::string before = slurp(second);
  run = iso("view " + kitten + " " + quoted(second) + " --cpu --out " + quoted(second));
  EXPECT_NE(run.exitCode, 0);
  EXPECT_NE(run.err.find("second.ppm"), std::string::npos) << run.err;
  EXPECT_EQ(slurp(second), before);
  // A truncated LAZ: the reader's error naming it, and the old picture stays.
  const std::vector<std::byte> laz = readFile(data / "laz" / "las12-f2-variable.laz");
  writeFile(dir / "cut.laz", std::vector<std::byte>(laz.begin(), laz.begin() + laz.size() / 2));
  std::ofstream(cpu) << "old picture";
  for (const char* mode : {"--cpu", "--headless"}) {
    run = iso("view " + quoted(dir / "cut.laz") + " " + mode + " --out " + quoted(cpu) + size);
    EXPECT_EQ(run.exitCode, 1) << mode;
    EXPECT_NE(run.err.find("cut.laz"), std::string::npos) << run.err;
    EXPECT_EQ(slurp(cpu), "old picture");
  }
}

// A raw scan in a window: the first picture as soon as points are read; M, L and the scene file
// change the shading, the layers and the opacity while it is open.
TEST(CliView, aRawScanOpensInAWindowWhoseKeysAndSceneFileChangeItsDrawing) {
  SKIP_WITHOUT_XDOTOOL();
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  ASSERT_TRUE(windowSession("image_window_session.sh", data / "kitten_normals.xyz", dir.path()));
  const std::string out = slurp(dir / "out.txt");
  EXPECT_NE(out.find("first picture"), std::string::npos) << out;
  EXPECT_NE(out.find("reloaded"), std::string::npos) << out;
  // The last title: eye-dome shading of two layers.
  EXPECT_NE(out.find("5210 points | eye-dome | 2 layers"), std::string::npos) << out;
  const auto lit = expectPicture(dir / "iso-screenshot-1.png", 300, 200);
  const auto seeThrough = expectPicture(dir / "final.png", 300, 200);
  size_t changed = 0;
  for (size_t i = 0; i < lit.size(); ++i) changed += lit[i] != seeThrough[i];
  EXPECT_GT(changed, lit.size() / 20);
}

// --draw pss in a window: the first full picture, a screenshot, an orbit (traced smaller while
// the camera moves), X and 1 (exact mode, no shadows) in the title, the last picture turned.
TEST(CliView, aPointSetSurfaceWindowTracesWhatChangesAndOrbits) {
  SKIP_WITHOUT_XDOTOOL();
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  ASSERT_TRUE(windowSession("pss_window_session.sh", data / "kitten_normals.xyz", dir.path()));
  const std::string out = slurp(dir / "out.txt");
  EXPECT_NE(out.find("first full picture"), std::string::npos) << out;
  EXPECT_NE(out.find("point set surface, exact mode | 5210 points | shadows off"),
            std::string::npos)
      << out;
  const auto first = expectPicture(dir / "iso-screenshot-1.png", 160, 120);
  const auto last = expectPicture(dir / "final.png", 160, 120);
  size_t changed = 0;
  for (size_t i = 0; i < first.size(); ++i) changed += first[i] != last[i];
  EXPECT_GT(changed, first.size() / 20);
}

// More read than fits --vram in a window: the points of the close view it opens at (part of
// the scan out of sight), then, once the camera has backed off and rests, those of the view it
// rests at (all of the scan in sight), each within the budget.
TEST(CliView, aWindowDrawsThePointsOfEachViewTheCameraRestsAtWhenNotAllFit) {
  SKIP_WITHOUT_XDOTOOL();
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  // Room for about 2,000 of the kitten's 5,210 points beside a 300 × 200 picture.
  ASSERT_TRUE(windowSession("refine_window_session.sh", data / "kitten_normals.xyz", dir.path(),
                            "20520000 0.1,0.25,1.0,0.1,0.25,0,0,1,0"));
  const std::string out = slurp(dir / "out.txt");
  const std::regex line(
      R"(drawing (\d+) points of 5210 read, chosen for the view from 5210: (\d+) where it looks)");
  std::vector<std::pair<size_t, size_t>> views;  // (drawn, where it looks)
  for (auto it = std::sregex_iterator(out.begin(), out.end(), line); it != std::sregex_iterator();
       ++it)
    views.emplace_back(std::stoul((*it)[1]), std::stoul((*it)[2]));
  ASSERT_EQ(views.size(), 2u) << out;
  for (const auto& [drawn, seen] : views) {
    EXPECT_GT(drawn, 1800u) << out;
    EXPECT_LT(drawn, 2300u) << out;
    EXPECT_LE(seen, drawn) << out;
  }
  EXPECT_LT(views[0].second, views[0].first) << out;  // the close view sees part of it
  EXPECT_EQ(views[1].second, views[1].first) << out;  // the far one all of it
  // The kitten fills more of the close view than of the far one.
  const auto coverage = [](const std::vector<uint32_t>& pixels) {
    size_t n = 0;
    for (uint32_t p : pixels) n += (p & 0xFFFFFF) != (pixels[0] & 0xFFFFFF);
    return double(n) / double(pixels.size());
  };
  const double close = coverage(expectPicture(dir / "iso-screenshot-1.png", 300, 200));
  const double far = coverage(expectPicture(dir / "iso-screenshot-2.png", 300, 200));
  EXPECT_GT(close, 2 * far) << close << " " << far;
}

// The tracer's window: K steps through the surface, the kept points as splats, both, and the
// kept points as image-space points (read when first asked for), then back to the surface.
TEST(CliView, theTracersWindowDrawsTheKeptPointsInImageSpaceOnKeyK) {
  SKIP_WITHOUT_XDOTOOL();
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  const auto kept = dir / "kept.iso";
  const CommandResult run =
      iso("convert --quiet --keep-points " + quoted(data / "kitten_normals.xyz") + " -o " +
          quoted(kept));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  ASSERT_TRUE(windowSession("mode_window_session.sh", kept, dir.path()));
  const std::string out = slurp(dir / "out.txt");
  EXPECT_NE(out.find("drawing 5210 kept points as image-space points"), std::string::npos) << out;
  const auto points = expectPicture(dir / "iso-screenshot-1.png", 240, 180);
  const auto surface = expectPicture(dir / "iso-screenshot-2.png", 240, 180);
  // Image-space points over their black background, a fifth of the picture or so; the surface
  // again under the tracer's sky.
  size_t drawn = 0;
  for (uint32_t p : points) drawn += p != points[0];
  EXPECT_EQ(points[0] & 0xFFFFFF, 0u);
  EXPECT_GT(drawn, points.size() / 20);
  EXPECT_LT(drawn, points.size() / 2);
  EXPECT_NE(surface[0] & 0xFFFFFF, 0u);
  // A file that keeps no points: the window says so and goes on drawing the surface.
  TempDir none;
  ASSERT_TRUE(windowSession("mode_window_session.sh", kittenIso(), none.path(), "none"));
  EXPECT_NE(slurp(none / "err.txt").find("keeps no points"), std::string::npos)
      << slurp(none / "err.txt");
  const auto still = expectPicture(none / "iso-screenshot-1.png", 240, 180);
  EXPECT_NE(still[0] & 0xFFFFFF, 0u);  // the tracer's sky
}

// The kept points of an .iso file drawn as image-space points: the level of detail that fits
// --vram (all of the kitten's here, or a subsample under a small budget), as the raw scan draws.
TEST(CliView, keptPointsOfAnIsoFileDrawAsImageSpacePointsUnderTheBudget) {
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  const std::string kitten = quoted(data / "kitten_normals.xyz");
  const auto kept = dir / "kept.iso";
  CommandResult run = iso("convert --quiet --keep-points " + kitten + " -o " + quoted(kept));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const std::string size = " --width 200 --height 160";
  const auto fromIso = dir / "iso.png", fromScan = dir / "scan.png", small = dir / "small.png";
  run = iso("view " + quoted(kept) + " --draw image --cpu --out " + quoted(fromIso) + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("5210 points from 1 file"), std::string::npos) << run.out;
  run = iso("view " + kitten + " --cpu --out " + quoted(fromScan) + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  uint32_t w = 0, h = 0;
  const auto a = readRgba8Image(fromIso, w, h), b = readRgba8Image(fromScan, w, h);
  const uint32_t sky = a[0];
  size_t both = 0, either = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    both += a[i] != sky && b[i] != sky;
    either += a[i] != sky || b[i] != sky;
  }
  EXPECT_GT(double(both) / double(either), 0.95) << both << " of " << either;
  // A budget with room for about 1,900 points: those the view needs (the kitten's kept points are
  // one chunk, with no coarser one: keep_points_test tests the cut of finer files).
  for (const std::string& input : {kitten, quoted(kept)}) {
    run = iso("view " + input + " --draw image --cpu --vram 18829000 --out " + quoted(small) +
              size);
    ASSERT_EQ(run.exitCode, 0) << run.err;
    const size_t drawn = std::stoul(run.out);
    EXPECT_LT(drawn, 2000u) << run.out;
    EXPECT_GT(drawn, 500u) << run.out;
    expectPicture(small, 200, 160);
    EXPECT_NE(run.out.find("chosen for the view from 5210"), std::string::npos) << run.out;
  }
}

// --draw pss: the kitten's points as a point set surface on the CPU reference, in the same
// silhouette as its image-space points; dispersion's three indices, and what is refused.
TEST(CliView, pointsDrawAsAPointSetSurfaceOnTheCpu) {
  TempDir dir;
  const std::string kitten =
      quoted(std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz");
  const std::string size = " --width 160 --height 128";
  const auto pss = dir / "pss.png", exact = dir / "exact.png", image = dir / "image.png";
  CommandResult run = iso("view " + kitten + " --draw pss --cpu --out " + quoted(pss) + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("point set surface (fast mode)"), std::string::npos) << run.out;
  run = iso("view " + kitten + " --draw pss --pss exact --cpu --out " + quoted(exact) + size +
            " --transparency 0.6 --ior 1.5,1.52,1.54");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("(exact mode)"), std::string::npos) << run.out;
  ASSERT_EQ(iso("view " + kitten + " --cpu --out " + quoted(image) + size).exitCode, 0);
  const auto a = expectPicture(pss, 160, 128), b = expectPicture(image, 160, 128);
  expectPicture(exact, 160, 128);
  size_t both = 0, either = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const bool x = (a[i] & 0xFFFFFF) != 0, y = (b[i] & 0xFFFFFF) != 0;
    both += x && y;
    either += x || y;
  }
  std::printf("kitten: point set surface against image-space points, IoU %.4f\n",
              double(both) / double(either));
  EXPECT_GT(double(both) / double(either), 0.9);
  // The GPU's picture is the CPU's.
  const auto gpu = dir / "gpu.png";
  run = iso("view " + kitten + " --draw pss --headless --out " + quoted(gpu) + size);
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto c = expectPicture(gpu, 160, 128);
  size_t unlike = 0;
  for (size_t i = 0; i < a.size(); ++i)
    for (int k = 0; k < 24; k += 8) {
      if (std::abs(int(a[i] >> k & 255) - int(c[i] >> k & 255)) > 8) {
        ++unlike;
        break;
      }
    }
  EXPECT_LT(double(unlike) / double(a.size()), 0.005) << unlike;
  // Three indices only for --draw pss.
  EXPECT_EQ(iso("view " + kitten + " --cpu --out x.png --ior 1.5,1.52,1.54").exitCode, 2);
  EXPECT_EQ(iso("view " + kitten + " --draw pss --cpu --out x.png --ior 5").exitCode, 2);
}

// --draw pss --volume-points: a blob of values inside the kitten, drawn as a volume through its
// glass surface (the scene file's transfer function), and what is refused.
TEST(CliView, scatteredValuesDrawAsAVolumeInsideAPointSetSurface) {
  TempDir dir;
  const std::string kitten =
      quoted(std::filesystem::path(ISO_TEST_DATA_DIR) / "kitten_normals.xyz");
  const auto blob = dir / "blob.ply";
  {
    std::ofstream out(blob);
    std::vector<std::array<float, 4>> points;
    for (int i = -12; i <= 12; ++i)
      for (int j = -12; j <= 12; ++j)
        for (int k = -12; k <= 12; ++k) {
          const float x = 0.025f * i, y = 0.035f * j, z = 0.02f * k;
          points.push_back({x, y, z, std::exp(-(x * x + y * y + z * z) / 0.05f)});
        }
    out << "ply\nformat ascii 1.0\nelement vertex " << points.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float value\n"
           "property float other\nend_header\n";
    for (const auto& p : points) out << p[0] << ' ' << p[1] << ' ' << p[2] << ' ' << p[3] << " 0\n";
  }
  const auto scene = dir / "scene.json";
  std::ofstream(scene) << R"({"volume": {"transfer": [[0, 0, 0, 1, 0], [1, 1, 0.5, 0, 12]]}})";
  const std::string common = " --draw pss --cpu --width 120 --height 120 --transparency 0.9 --ior 1.1";
  const auto with = dir / "with.png", without = dir / "without.png";
  CommandResult run = iso("view " + kitten + common + " --out " + quoted(with) + " --scene " +
                          quoted(scene) + " --volume-points " + quoted(blob) + " --volume value");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("a volume of 15625 points inside it"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("a transfer function of 2 points"), std::string::npos) << run.out;
  ASSERT_EQ(iso("view " + kitten + common + " --out " + quoted(without)).exitCode, 0);
  const auto a = expectPicture(with, 120, 120), b = expectPicture(without, 120, 120);
  size_t redder = 0;  // the blob emits red and green, absorbs the blue behind
  for (size_t i = 0; i < a.size(); ++i) redder += (a[i] & 255) > (b[i] & 255) + 8;
  EXPECT_GT(redder, a.size() / 50) << redder;
  // A scalar it does not have, two without a name, a volume without points or without pss.
  run = iso("view " + kitten + common + " --out x.png --volume-points " + quoted(blob) +
            " --volume density");
  EXPECT_NE(run.exitCode, 0);
  EXPECT_NE(run.err.find("blob.ply"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("value, other"), std::string::npos) << run.err;
  EXPECT_EQ(iso("view " + kitten + common + " --out x.png --volume-points " + quoted(blob)).exitCode, 2);
  EXPECT_EQ(iso("view " + kitten + common + " --out x.png --volume value").exitCode, 2);
  EXPECT_EQ(iso("view " + kitten + " --cpu --out x.png --volume-points " + quoted(blob)).exitCode, 2);
  // The same volume kept in an .iso file (iso convert --volume-points) draws as from its points:
  // their positions (2^-24 of the frame) and values (1/65535 of their span) are kept that closely.
  const auto kept = dir / "kept.iso";
  run = iso("convert --quiet --keep-points " + kitten + " -o " + quoted(kept) +
            " --volume-points " + quoted(blob) + " --keep-scalar value");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  const auto fromFile = dir / "from-file.png", fromPoints = dir / "from-points.png";
  run = iso("view " + quoted(kept) + common + " --out " + quoted(fromFile) + " --scene " +
            quoted(scene) + " --volume value");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("a volume of 15625 points inside it"), std::string::npos) << run.out;
  ASSERT_EQ(iso("view " + quoted(kept) + common + " --out " + quoted(fromPoints) + " --scene " +
                quoted(scene) + " --volume-points " + quoted(blob) + " --volume value")
                .exitCode,
            0);
  const auto c = expectPicture(fromFile, 120, 120), d = expectPicture(fromPoints, 120, 120);
  size_t differ = 0, redderKept = 0;
  for (size_t i = 0; i < c.size(); ++i) {
    for (int shift = 0; shift < 24; shift += 8)
      differ += std::abs(int((c[i] >> shift) & 255) - int((d[i] >> shift) & 255)) > 2 ? 1 : 0;
    redderKept += (c[i] & 255) > (b[i] & 255) + 8;
  }
  EXPECT_LT(differ, c.size() * 3 / 100) << differ;
  EXPECT_GT(redderKept, c.size() / 50) << redderKept;
  run = iso("view " + quoted(kept) + common + " --out x.png --volume density");
  EXPECT_EQ(run.exitCode, 2);
  EXPECT_NE(run.err.find("they keep: value"), std::string::npos) << run.err;
  std::ofstream(scene) << R"({"volume": {"transfer": [[1, 0, 0, 1, 0], [0, 1, 1, 1, 1]]}})";
  run = iso("view " + kitten + common + " --out x.png --scene " + quoted(scene) +
            " --volume-points " + quoted(blob) + " --volume value");
  EXPECT_NE(run.exitCode, 0);
  EXPECT_NE(run.err.find("increasing value"), std::string::npos) << run.err;
}

// --with-pss: a point set surface among an .iso file's objects, in one tracer (shaders/trace.h):
// a second kitten as a glass point set surface with scattered values glowing inside, beside the
// kitten's ISO surface and its kept points as splats (--draw both). The GPU draws what the CPU
// reference draws; the point set surface is where its points are, and its volume shows.
TEST(CliView, aPointSetSurfaceAVolumeAnIsoSurfaceAndSplatsMixInOneScene) {
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  const PointCloud kitten = readPointFile(data / "kitten_normals.xyz");
  double lo = 1e30, hi = -1e30;
  for (const auto& p : kitten.positions) {
    lo = std::min(lo, p.x);
    hi = std::max(hi, p.x);
  }
  const double shift = 1.1 * (hi - lo);  // the second kitten to the right of the first
  PointCloud second = kitten;
  for (auto& p : second.positions) p.x += shift;
  writePly(dir / "second.ply", second);
  {
    std::ofstream out(dir / "blob.ply");
    out << "ply\nformat ascii 1.0\nelement vertex 4913\nproperty float x\nproperty float y\n"
           "property float z\nproperty float value\nend_header\n";
    for (int i = -8; i <= 8; ++i)
      for (int j = -8; j <= 8; ++j)
        for (int k = -8; k <= 8; ++k) {
          const double x = 0.035 * i, y = 0.045 * j, z = 0.03 * k;
          out << x + shift << ' ' << y << ' ' << z << ' '
              << std::exp(-(x * x + y * y + z * z) / 0.05) << "\n";
        }
  }
  const auto kept = dir / "kept.iso";
  ASSERT_EQ(iso("convert --quiet --keep-points " + quoted(data / "kitten_normals.xyz") + " -o " +
                quoted(kept))
                .exitCode,
            0);
  const auto scene = dir / "scene.json";
  std::ofstream(scene) << R"({"volume": {"transfer": [[0, 0, 0, 1, 0], [1, 1, 0.5, 0, 12]]}})";
  const std::string camera = fmt::format(" --camera {},0.15,2.2,{},0,0,0,1,0", shift / 2, shift / 2);
  const std::string common = " --draw both --width 160 --height 96 --transparency 0.7 --ior 1.1" +
                             camera + " --scene " + quoted(scene);
  const std::string mixed =
      " --with-pss " + quoted(dir / "second.ply") + " --volume-points " + quoted(dir / "blob.ply");
  const auto cpu = dir / "cpu.png", gpu = dir / "gpu.png", alone = dir / "alone.png",
             empty = dir / "empty.png";
  CommandResult run = iso("view " + quoted(kept) + common + mixed + " --cpu --out " + quoted(cpu));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("a volume of 4913 points inside it"), std::string::npos) << run.out;
  run = iso("view " + quoted(kept) + common + mixed + " --headless --out " + quoted(gpu));
  ASSERT_EQ(run.exitCode, 0) << run.err;
  ASSERT_EQ(iso("view " + quoted(kept) + common + " --cpu --out " + quoted(alone)).exitCode, 0);
  ASSERT_EQ(iso("view " + quoted(kept) + common + " --with-pss " + quoted(dir / "second.ply") +
                " --cpu --out " + quoted(empty))
                .exitCode,
            0);
  const auto a = expectPicture(cpu, 160, 96), b = expectPicture(gpu, 160, 96),
             c = expectPicture(alone, 160, 96), d = expectPicture(empty, 160, 96);
  size_t unlike = 0, left = 0, right = 0, leftChanged = 0, rightChanged = 0, redder = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 24; k += 8)
      if (std::abs(int(a[i] >> k & 255) - int(b[i] >> k & 255)) > 8) {
        ++unlike;
        break;
      }
    const bool isRight = i % 160 >= 80;
    const bool changed = a[i] != c[i];
    (isRight ? right : left) += 1;
    (isRight ? rightChanged : leftChanged) += changed ? 1 : 0;
    redder += (a[i] & 255) > (d[i] & 255) + 8 ? 1 : 0;  // the volume glows red and yellow
  }
  EXPECT_LT(double(unlike) / double(a.size()), 0.005) << unlike;
  // The second kitten is on the right: most of what it changed is there.
  EXPECT_GT(rightChanged, right / 10) << rightChanged;
  EXPECT_GT(rightChanged, 3 * leftChanged) << leftChanged;
  EXPECT_GT(redder, a.size() / 100) << redder;
  // --with-pss goes into an .iso file's scene.
  EXPECT_EQ(iso("view " + quoted(data / "kitten_normals.xyz") + " --cpu --out x.png --with-pss " +
                quoted(dir / "second.ply"))
                .exitCode,
            2);
}

// iso eval --against-pss: the ISO surface against the point set surface of its kept points,
// the kitten (and the bunny, with ../shared/data): the silhouettes agree (IoU ≥ 0.97 for the
// bunny, as the issue asks), depths mostly within a spacing.
TEST(CliView, evalMeasuresTheIsoSurfaceAgainstThePointSetSurfaceOfItsPoints) {
  TempDir dir;
  const auto data = std::filesystem::path(ISO_TEST_DATA_DIR);
  std::vector<std::pair<std::filesystem::path, double>> scans = {
      {data / "kitten_normals.xyz", 0.95}};
  const auto bunny = std::filesystem::path(ISO_SHARED_DATA_DIR) / "bunny_zipper.ply";
  if (std::filesystem::exists(bunny)) scans.push_back({bunny, 0.97});
  for (const auto& [scan, least] : scans) {
    const auto kept = dir / "kept.iso";
    ASSERT_EQ(iso("convert --quiet --force --keep-points " + quoted(scan) + " -o " + quoted(kept))
                  .exitCode,
              0);
    const auto pictures = dir / "pictures";
    const CommandResult run = iso("eval " + quoted(kept) + " --against-pss --size 96 --pictures " +
                                  quoted(pictures));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    const auto j = nlohmann::json::parse(run.out);
    // The pictures are those measured: their silhouettes give the reported IoU, their shading
    // the reported PSNR (background 0, a hit at least 38).
    size_t both = 0, either = 0;
    double squared = 0.0;
    for (const char* axis : {"+x", "-x", "+y", "-y", "+z", "-z"}) {
      const auto a = expectPicture(pictures / (std::string("view") + axis + "-iso.png"), 96, 96);
      const auto b = expectPicture(pictures / (std::string("view") + axis + "-pss.png"), 96, 96);
      // The difference is mostly the background where the two agree: its size is what is checked.
      uint32_t w = 0, h = 0;
      readRgba8Image(pictures / (std::string("view") + axis + "-difference.png"), w, h);
      EXPECT_EQ(w, 96u);
      EXPECT_EQ(h, 96u);
      for (size_t i = 0; i < a.size(); ++i) {
        const int x = int(a[i] & 255), y = int(b[i] & 255);
        both += x > 0 && y > 0;
        either += x > 0 || y > 0;
        squared += double(x - y) * double(x - y);
      }
    }
    EXPECT_NEAR(double(both) / double(either), j["silhouette_iou"].get<double>(), 1e-9);
    EXPECT_NEAR(10.0 * std::log10(255.0 * 255.0 / (squared / (6.0 * 96 * 96))),
                j["psnr_db"].get<double>(), 1e-6);
    std::printf("%s: IoU %.4f, depth median %.3f spacings (%.1f %% within one), normals median "
                "%.2f degrees, PSNR %.1f dB, the ISO tracer %.1f times the PSS exact mode's "
                "rays/s\n",
                scan.filename().c_str(), j["silhouette_iou"].get<double>(),
                j["depth_spacings"]["median"].get<double>(),
                100.0 * j["depth_spacings"]["within_one"].get<double>(),
                j["normal_degrees"]["median"].get<double>(), j["psnr_db"].get<double>(),
                j["iso_over_pss_speed"].get<double>());
    EXPECT_GE(j["silhouette_iou"].get<double>(), least) << scan;
    EXPECT_LT(j["depth_spacings"]["median"].get<double>(), 0.5) << scan;
    EXPECT_GT(j["depth_spacings"]["within_one"].get<double>(), 0.8) << scan;
    EXPECT_GT(j["pss_exact_rays_per_second"].get<double>(), 0.0) << scan;  // speed: bench pss
  }
  // A file that keeps no points has no point set surface.
  const CommandResult none = iso("eval " + quoted(kittenIso()) + " --against-pss --size 32");
  EXPECT_NE(none.exitCode, 0);
  EXPECT_NE(none.err.find("keeps no points"), std::string::npos) << none.err;
  EXPECT_EQ(iso("eval " + quoted(kittenIso()) + " --against-pss --size 2").exitCode, 2);
}

TEST(CliView, causticsPutAGroundUnderTheSurfaceAndSayHowManyPhotonsTheyTraced) {
  TempDir dir;
  const std::string file = quoted(kittenIso());
  const auto out = dir / "glass.png", plain = dir / "plain.png";
  const std::string glass = " --width 96 --height 96 --transparency 0.9 --out ";
  for (const char* mode : {"--headless", "--cpu"}) {
    const CommandResult run =
        iso("view " + file + " " + mode + glass + quoted(out) + " --caustics 20000");
    ASSERT_EQ(run.exitCode, 0) << run.err;
    EXPECT_NE(run.out.find("caustics: 20000 photons"), std::string::npos) << run.out;
  }
  // The ground it put there, lit by the caustic: the picture differs from one with a ground
  // and no caustics only where the light went through the glass.
  ASSERT_EQ(iso("view " + file + " --cpu" + glass + quoted(plain) + " --ground").exitCode, 0);
  uint32_t w = 0, h = 0;
  const auto with = readRgba8Image(out, w, h), without = readRgba8Image(plain, w, h);
  ASSERT_EQ(with.size(), without.size());
  size_t brighter = 0, darker = 0;
  for (size_t i = 0; i < with.size(); ++i) {
    const int a = int(with[i] >> 8 & 0xFF), b = int(without[i] >> 8 & 0xFF);
    brighter += a > b;
    darker += a < b;
  }
  std::printf("caustics: %zu of %zu pixels brighter, %zu darker\n", brighter, with.size(), darker);
  EXPECT_GT(brighter, 20u);
  EXPECT_EQ(darker, 0u);
}

TEST(CliView, impossibleOptionsAreUsageErrors) {
  const std::string file = quoted(kittenIso());
  EXPECT_EQ(iso("view " + file + " --headless").exitCode, 2);  // no --out
  EXPECT_EQ(iso("view " + file + " --headless --cpu --out x.png").exitCode, 2);
  const CommandResult vram = iso("view " + file + " --headless --out x.png --vram lots");
  EXPECT_EQ(vram.exitCode, 2);
  EXPECT_NE(vram.err.find("--vram"), std::string::npos) << vram.err;
  EXPECT_EQ(iso("view " + file + " --headless --out x.png --light spot:1,2,3").exitCode, 2);
  EXPECT_EQ(iso("view " + file + " --headless --out x.png --reflectivity 0.7 --transparency 0.5")
                .exitCode,
            2);
  EXPECT_EQ(iso("view /nonexistent.iso --headless --out x.png").exitCode, 2);
  EXPECT_EQ(iso("view " + file + " --headless --out x.png --json").exitCode, 2);  // not --bench
  EXPECT_EQ(iso("view " + file + " --bench --frames-in-flight 4").exitCode, 2);
  const CommandResult faces = iso("view " + file + " --cpu --out x.png --backfaces invisible");
  EXPECT_EQ(faces.exitCode, 2);
  EXPECT_NE(faces.err.find("--backfaces"), std::string::npos) << faces.err;
  const CommandResult draw = iso("view " + file + " --cpu --out x.png --draw splats");
  EXPECT_EQ(draw.exitCode, 2);
  EXPECT_NE(draw.err.find("--draw"), std::string::npos) << draw.err;
  EXPECT_EQ(iso("view " + file + " --cpu --out x.png --points --draw both").exitCode, 2);
  EXPECT_EQ(iso("view " + file + " --bench --one-kernel --wavefront").exitCode, 2);
  for (const char* photons : {"-5", "many", "1e12"}) {
    const CommandResult caustics =
        iso("view " + file + " --cpu --out x.png --caustics " + std::string(photons));
    EXPECT_EQ(caustics.exitCode, 2) << photons;
    EXPECT_NE(caustics.err.find("--caustics"), std::string::npos) << caustics.err;
  }
  // Splats of a file that keeps no points: the file is named, nothing is written.
  for (const char* mode : {"--cpu", "--headless"}) {
    const CommandResult none = iso("view " + file + " " + mode + " --out x.png --points");
    EXPECT_EQ(none.exitCode, 1) << mode;
    EXPECT_NE(none.err.find("keeps no points"), std::string::npos) << none.err;
    EXPECT_NE(none.err.find(kittenIso().filename().string()), std::string::npos) << none.err;
  }
  const CommandResult small = iso("view " + file + " --headless --out x.png --vram 4K");
  EXPECT_EQ(small.exitCode, 1);
  EXPECT_NE(small.err.find("--vram"), std::string::npos) << small.err;
  EXPECT_FALSE(std::filesystem::exists("x.png"));
  // A picture of a kind this build cannot write: refused before any work. Builds without
  // OpenImageIO write PNG and PPM files only, and say so.
  TempDir dir;
  const CommandResult kind =
      iso("view " + file + " --cpu --out " + quoted(dir / "x.not-an-image-format"));
  EXPECT_EQ(kind.exitCode, 2);
  EXPECT_NE(kind.err.find("--out"), std::string::npos) << kind.err;
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  const CommandResult exr =
      iso("view " + file + " --cpu --out " + quoted(dir / "x.exr") + " --width 16 --height 16");
  EXPECT_EQ(exr.exitCode, ISO_WITH_OPENIMAGEIO ? 0 : 2) << exr.err;
  EXPECT_EQ(std::filesystem::exists(dir / "x.exr"), bool(ISO_WITH_OPENIMAGEIO));
  if (!ISO_WITH_OPENIMAGEIO) {
    EXPECT_NE(exr.err.find("this build of iso has no OpenImageIO"), std::string::npos) << exr.err;
  }
}

}  // namespace
}  // namespace iso::test
