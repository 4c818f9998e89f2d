// Damaged .iso files through every command, as a user runs them: each command either refuses the
// file (exit 1, a message naming it, nothing written) or answers exactly as it does on the intact
// file, and none needs much more memory for a hostile size than for the intact file.
#include <gtest/gtest.h>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "iso/reader.h"
#include "tests/cli_support.h"

namespace iso::test {
namespace {

// The intact file: a sphere scan converted with its points kept (a points chunk), cut into many
// surface chunks, raw and zstd.
const std::filesystem::path& intactIso() {
  static TempDir dir;
  static const std::filesystem::path path = [] {
    const auto ply = dir / "sphere.ply", out = dir / "sphere.iso";
    EXPECT_EQ(runIso("gen sphere -n 3000 -o " + quoted(ply)).exitCode, 0);
    const CommandResult run = runIso("convert --quiet --keep-points --chunk-nodes 100 " +
                                     quoted(ply) + " -o " + quoted(out));
    EXPECT_EQ(run.exitCode, 0) << run.err;
    return out;
  }();
  return path;
}

// A scene with a light, for `iso bake`.
const std::filesystem::path& bakeScene() {
  static TempDir dir;
  static const std::filesystem::path path = [] {
    const auto scene = dir / "scene.json";
    std::ofstream(scene) << R"({"lights": [{"type": "point", "position": [2, 3, 4]}]})";
    return scene;
  }();
  return path;
}

// How a command's answer is compared with its answer on the intact file.
enum class Answer { Text, Json, File, Vdb };

struct Command {
  const char* name;
  std::string arguments;  // FILE: the .iso file; INTACT: the intact one; OUT: the output file
  Answer answer;
  std::string output = {};  // the output file's name
};

const std::vector<Command>& commands() {
  static const std::vector<Command> list = {
      {"info", "info FILE", Answer::Text},
      {"info --json --chunks", "info --json --chunks FILE", Answer::Json},
      {"view --headless", "view FILE --headless --out OUT --width 32 --height 24", Answer::File,
       "picture.png"},
      {"view --cpu", "view FILE --cpu --out OUT --width 32 --height 24", Answer::File,
       "picture.png"},
      {"eval --shape", "eval FILE --shape sphere --rays 200 --samples 2000", Answer::Json},
      {"eval --against", "eval FILE --against INTACT", Answer::Json},
      {"eval INTACT --against", "eval INTACT --against FILE", Answer::Json},
      {"eval --visibility", "eval FILE --visibility --views 0", Answer::Json},
      {"export --mesh", "export FILE --mesh OUT", Answer::File, "mesh.ply"},
      {"export --vdb", "export FILE --vdb OUT", Answer::Vdb, "surface.vdb"},
      {"export --points", "export FILE --points OUT", Answer::File, "points.ply"},
      {"bake", "bake FILE -o OUT --scene SCENE --bounces 1 --bake-rays 4", Answer::File,
       "lit.iso"},
  };
  static const std::vector<Command> withoutVdb = [] {  // ISO_WITH_OPENVDB=OFF
    std::vector<Command> l = list;
    std::erase_if(l, [](const Command& c) { return c.answer == Answer::Vdb; });
    return l;
  }();
  return ISO_WITH_OPENVDB ? list : withoutVdb;
}

std::string replaced(std::string text, const std::string& what, const std::string& with) {
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + with.size()))
    text.replace(at, what.size(), with);
  return text;
}

// What a command answered on a file: its exit, messages, output, peak memory, and whether its
// output folder holds anything besides the answer.
struct Outcome {
  CommandResult run;
  std::string answer;  // the part compared with the intact file's
  std::vector<std::filesystem::path> written;
};

// The answer in a form that does not depend on the file's name (or size, for info).
std::string answerOf(const Command& c, const CommandResult& run, const std::filesystem::path& out) {
  switch (c.answer) {
    case Answer::Text: {
      std::istringstream lines(run.out);
      std::string line, kept;
      while (std::getline(lines, line))
        if (line.rfind("file", 0) != 0 && line.rfind("size", 0) != 0) kept += line + "\n";
      return kept;
    }
    case Answer::Json: {
      nlohmann::json j = nlohmann::json::parse(run.out);
      for (const char* key : {"file", "against", "file_size"}) j.erase(key);
      return j.dump();
    }
    case Answer::File:
      return slurp(out);
    case Answer::Vdb: {
      // An OpenVDB file holds a fresh UUID (36 characters from byte 21): not part of the answer.
      std::string bytes = slurp(out);
      EXPECT_GT(bytes.size(), 57u);
      EXPECT_EQ(bytes.substr(29, 1) + bytes.substr(34, 1) + bytes.substr(39, 1), "---");
      return bytes.replace(21, 36, 36, '-');
    }
  }
  return {};
}

Outcome runOn(const Command& c, const std::filesystem::path& file) {
  TempDir dir;
  const auto out = dir / (c.output.empty() ? "none" : c.output);
  std::string arguments = replaced(c.arguments, "INTACT", quoted(intactIso()));
  arguments = replaced(arguments, "SCENE", quoted(bakeScene()));
  arguments = replaced(replaced(arguments, "FILE", quoted(file)), "OUT", quoted(out));
  Outcome o;
  o.run = runIso(arguments);
  if (o.run.exitCode == 0) o.answer = answerOf(c, o.run, out);
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    o.written.push_back(entry.path());
  return o;
}

// The intact file's outcome of each command, run once.
const Outcome& intactOutcome(const Command& c) {
  static std::map<std::string, Outcome> outcomes;
  auto found = outcomes.find(c.name);
  if (found == outcomes.end()) found = outcomes.emplace(c.name, runOn(c, intactIso())).first;
  return found->second;
}

// Whether a failed run is `iso view --headless` without a Vulkan device (no lavapipe, no GPU):
// it fails on the intact file too, and the damaged files cannot be shown to it.
bool isHeadlessWithoutDevice(const Command& c, const Outcome& o,
                             const std::filesystem::path& file) {
  if (c.arguments.find("--headless") == std::string::npos || o.run.exitCode == 0 ||
      o.run.err.find(file.string()) != std::string::npos)
    return false;
  static const bool noDevice = [&] {
    const bool fails = intactOutcome(c).run.exitCode != 0;
    if (fails) std::fprintf(stderr, "view --headless fails on the intact file: not checked\n");
    return fails;
  }();
  return noDevice;
}

// What a mutant is checked for besides its answers.
struct Expect {
  bool memory = false;  // measure each command's peak memory against the intact file's
  // Commands that list the chunk table without reading payloads (`iso info`) may answer what the
  // table declares, when the damage lies in a payload whose checksum was made to match.
  bool tableListed = false;
};

// Every command on the damaged bytes: a refusal naming the file that leaves nothing, or the intact
// file's answer; verify always refuses. Returns the largest peak memory over the commands less
// that command's peak on the intact file (KiB), when asked to measure it.
long expectRefusedOrUnchanged(const std::string& name, const std::vector<std::byte>& bytes,
                              Expect expect = {}) {
  SCOPED_TRACE(name);
  TempDir dir;
  const auto file = dir / (name + ".iso");
  writeFile(file, bytes);
  const CommandResult verify = runIso("verify " + quoted(file));
  EXPECT_EQ(verify.exitCode, 1) << verify.out;
  EXPECT_NE(verify.err.find(file.string()), std::string::npos) << verify.err;
  long growth = 0;
  for (const Command& c : commands()) {
    SCOPED_TRACE(c.name);
    const Outcome o = runOn(c, file);
    if (isHeadlessWithoutDevice(c, o, file)) continue;
    if (o.run.exitCode != 0) {
      EXPECT_EQ(o.run.exitCode, 1) << o.run.err;
      EXPECT_NE(o.run.err.find(file.string()), std::string::npos) << o.run.err;
      EXPECT_TRUE(o.written.empty()) << o.written.front();
    }
    if (o.run.exitCode != 0 && !expect.memory) continue;
    const Outcome& intact = intactOutcome(c);  // run only when needed: each run takes a while
    EXPECT_EQ(intact.run.exitCode, 0) << intact.run.err;
    growth = std::max(growth, o.run.peakRssKiB - intact.run.peakRssKiB);
    const bool listsTable = std::string(c.name).rfind("info", 0) == 0;
    if (o.run.exitCode == 0 && !(expect.tableListed && listsTable)) {
      EXPECT_EQ(o.answer, intact.answer) << "a different answer from a damaged file";
    }
  }
  return growth;
}

// The intact file's bytes, and where its chunks are.
class CliDamaged : public ::testing::Test {
 protected:
  void SetUp() override {
    bytes_ = readFile(intactIso());
    const Reader reader = Reader::fromMemory(bytes_, "intact");
    chunks_.assign(reader.chunks().begin(), reader.chunks().end());
    table_ = chunks_.empty() ? 0 : get(bytes_.size() - 64);
  }
  uint64_t get(size_t at) const {
    uint64_t v = 0;
    std::memcpy(&v, bytes_.data() + at, 8);
    return v;
  }
  template <typename T>
  static void put(std::vector<std::byte>& b, size_t at, T value) {
    std::memcpy(b.data() + at, &value, sizeof(T));
  }
  // The first chunk for which `pick` holds.
  const ChunkInfo& chunk(const std::function<bool(const ChunkInfo&)>& pick) const {
    for (const ChunkInfo& c : chunks_)
      if (pick(c)) return c;
    throw std::logic_error("the intact file has no such chunk");
  }
  size_t entry(const ChunkInfo& c) const { return size_t(table_) + 80 * c.id; }
  // The intact bytes with one byte of a chunk's payload flipped (its checksum left as it was).
  std::vector<std::byte> flipped(const ChunkInfo& c) const {
    std::vector<std::byte> b = bytes_;
    b[c.offset + c.storedSize / 2] ^= std::byte{0x04};
    return b;
  }
  // The intact bytes with the frame's first origin component and size replaced (resealed).
  std::vector<std::byte> frame(double origin, double size) {
    return resealed([&](auto& b) {
      put<double>(b, 24, origin);
      put<double>(b, 48, size);
    });
  }
  // The intact bytes with a change, every structure's checksum recomputed.
  std::vector<std::byte> resealed(const std::function<void(std::vector<std::byte>&)>& change) {
    std::vector<std::byte> b = bytes_;
    change(b);
    resealChecksums(b);
    return b;
  }

  std::vector<std::byte> bytes_;
  std::vector<ChunkInfo> chunks_;
  uint64_t table_ = 0;
};

bool isTopSurface(const ChunkInfo& c) { return c.kind == 1 && c.parent == kNoParent; }

TEST_F(CliDamaged, aFlippedSurfacePayloadByteIsRefusedByEveryCommandThatReadsIt) {
  const ChunkInfo& top = chunk(isTopSurface);  // every surface reader loads it
  ASSERT_EQ(top.codec, Codec::Zstd);
  const ChunkInfo& raw =
      chunk([](const ChunkInfo& c) { return c.kind == 1 && c.codec == Codec::Raw; });
  expectRefusedOrUnchanged("zstd-surface-flip", flipped(top));
  expectRefusedOrUnchanged("raw-surface-flip", flipped(raw));
}

TEST_F(CliDamaged, aFlippedPointsPayloadByteIsRefusedByEveryCommandThatReadsIt) {
  expectRefusedOrUnchanged("points-flip",
                           flipped(chunk([](const ChunkInfo& c) { return c.kind == 2; })));
}

// `iso info` prints the chunk table's figures without reading a payload: on a file with a flipped
// payload byte it answers as on the intact file and says, in text and JSON, that it checked no
// payload; `iso verify` names the chunk.
TEST_F(CliDamaged, infoSaysThatItChecksNoPayloadAndVerifyFindsTheFlippedByte) {
  const ChunkInfo& top = chunk(isTopSurface);
  TempDir dir;
  const auto file = dir / "flipped.iso";
  writeFile(file, flipped(top));
  const std::string notChecked =
      "payloads    not checked (the figures above are the chunk table's): iso verify checks them\n";
  for (const auto& path : {intactIso(), file}) {
    SCOPED_TRACE(path.string());
    CommandResult run = runIso("info " + quoted(path));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    EXPECT_NE(run.out.find(notChecked), std::string::npos) << run.out;
    run = runIso("info --json " + quoted(path));
    ASSERT_EQ(run.exitCode, 0) << run.err;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    ASSERT_TRUE(j.contains("payloads_checked"));
    EXPECT_EQ(j["payloads_checked"], false);
  }
  const Command text = {"info", "info FILE", Answer::Text};
  EXPECT_EQ(runOn(text, file).answer, intactOutcome(text).answer);
  const CommandResult verify = runIso("verify " + quoted(file));
  EXPECT_EQ(verify.exitCode, 1);
  EXPECT_NE(verify.err.find(file.string()), std::string::npos) << verify.err;
  EXPECT_NE(verify.err.find("chunk " + std::to_string(top.id) + " "), std::string::npos)
      << verify.err;
  EXPECT_NE(verify.err.find("checksum mismatch"), std::string::npos) << verify.err;
}

TEST_F(CliDamaged, metadataWithAByteOrderMarkIsRejectedByVerifyAndReadAlikeByTheRest) {
  std::vector<std::byte> b = bytes_;
  const uint64_t metadata = get(b.size() - 64 + 16), size = get(b.size() - 64 + 24);
  const std::array<std::byte, 3> mark = {std::byte{0xEF}, std::byte{0xBB}, std::byte{0xBF}};
  b.insert(b.begin() + ptrdiff_t(metadata), mark.begin(), mark.end());
  put<uint64_t>(b, b.size() - 64 + 24, size + 3);
  resealChecksums(b);
  expectRefusedOrUnchanged("bom", b);
}

// (tests/format/ tries every rule of counts and frames; here one of each class meets every
// command.)
TEST_F(CliDamaged, anImpossiblePointCountIsRefusedByEveryCommand) {
  const ChunkInfo& child = chunk([](const ChunkInfo& c) { return c.kind == 1 && c.parent == 0; });
  expectRefusedOrUnchanged("surface-count", resealed([&](auto& b) {
                             put<uint64_t>(b, entry(child) + 40, ~uint64_t{0});
                           }));
}

TEST_F(CliDamaged, impossibleFramesAreRefusedByEveryCommand) {
  expectRefusedOrUnchanged("subnormal-size", frame(0.0, std::numeric_limits<double>::denorm_min()));
  expectRefusedOrUnchanged("far-origin", frame(1e300, 2.0));
}

TEST_F(CliDamaged, hugeRawSizesAreRefusedBeforeTheMemoryIsTaken) {
  const ChunkInfo& top = chunk(isTopSurface);
  ASSERT_EQ(top.codec, Codec::Zstd);
  // The table alone declares 2^30 bytes.
  const long tableGrowth = expectRefusedOrUnchanged(
      "raw-size", resealed([&](auto& b) { put<uint64_t>(b, entry(top) + 16, uint64_t{1} << 30); }),
      {.memory = true});
  // The top chunk's payload, up to the next payload, becomes one zstd frame declaring 2^27 bytes
  // in its header as in the table, its checksum right: one Raw block that holds far fewer.
  const uint64_t room = chunks_[top.id + 1].offset - top.offset;
  ASSERT_GE(room, 4096u);
  const uint32_t declared = uint32_t{1} << 27, content = uint32_t(room) - 12;
  std::vector<std::byte> lie = {std::byte{0x28}, std::byte{0xB5}, std::byte{0x2F}, std::byte{0xFD},
                                std::byte{0xA0}};  // 4-byte content size, single segment
  for (int i = 0; i < 4; ++i) lie.push_back(std::byte(declared >> (8 * i)));
  for (int i = 0; i < 3; ++i) lie.push_back(std::byte((1u | content << 3) >> (8 * i)));
  lie.resize(room, std::byte{7});
  const long frameGrowth = expectRefusedOrUnchanged(
      "frame-size", resealed([&](auto& b) {
        std::memcpy(b.data() + top.offset, lie.data(), lie.size());
        put<uint64_t>(b, entry(top) + 8, room);
        put<uint64_t>(b, entry(top) + 16, declared);
        put<uint64_t>(b, entry(top) + 24, XXH3_64bits(lie.data(), lie.size()));
      }),
      {.memory = true, .tableListed = true});
  // No command took anywhere near the declared sizes (2^20 and 2^17 KiB).
  EXPECT_LT(tableGrowth, 64 * 1024);
  EXPECT_LT(frameGrowth, 64 * 1024);
}

TEST_F(CliDamaged, truncatedFilesAndDamagedTrailersAreRefusedByEveryCommand) {
  expectRefusedOrUnchanged("truncated",
                           {bytes_.begin(), bytes_.begin() + ptrdiff_t(bytes_.size() / 2)});
  std::vector<std::byte> footer = bytes_;
  footer[footer.size() - 30] ^= std::byte{0x01};
  expectRefusedOrUnchanged("trailer-flip", footer);
}

}  // namespace
}  // namespace iso::test
