// The writer never leaves an acceptable file at the output path unless it finished, never harms a
// file already there, reports failed writes (a full disk) with the file name, and rejects invalid
// chunk descriptions.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <thread>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/lighting.h"
#include "iso/points.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "tests/support/support.h"

namespace iso {
namespace {

std::vector<std::filesystem::path> listDirectory(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> entries;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    entries.push_back(e.path().filename());
  std::sort(entries.begin(), entries.end());
  return entries;
}

const std::vector<std::byte> kOld = {std::byte{'o'}, std::byte{'l'}, std::byte{'d'}};

TEST(Writer, abandonedWriteLeavesNothingBehind) {
  test::TempDir dir;
  {
    Writer writer(dir / "out.iso", FileHeader{});
    writer.addChunk({}, std::vector<std::byte>(5000, std::byte{1}));
    EXPECT_TRUE(std::filesystem::exists(writer.temporaryPath()));
    EXPECT_EQ(writer.temporaryPath().parent_path(), dir.path());
  }
  EXPECT_TRUE(listDirectory(dir.path()).empty());
}

TEST(Writer, existingFileSurvivesUntilFinishReplacesIt) {
  test::TempDir dir;
  test::writeFile(dir / "out.iso", kOld);
  {
    Writer writer(dir / "out.iso", FileHeader{});
    writer.addChunk({}, std::vector<std::byte>(100, std::byte{1}));
    EXPECT_EQ(test::readFile(dir / "out.iso"), kOld);
    writer.abandon();
  }
  EXPECT_EQ(test::readFile(dir / "out.iso"), kOld);
  {
    Writer writer(dir / "out.iso", FileHeader{});
    writer.addChunk({}, std::vector<std::byte>(100, std::byte{1}));
    writer.finish();
  }
  EXPECT_EQ(Reader::open(dir / "out.iso").chunks().size(), 1u);
  EXPECT_EQ(listDirectory(dir.path()), std::vector<std::filesystem::path>{"out.iso"});
}

TEST(Writer, failedWriteOnFullDiskNamesTheFileAndLeavesNothing) {
  // A file size limit makes write() fail the way a full disk does; run it in a child process so the
  // limit cannot leak into other tests.
  test::TempDir dir;
  test::writeFile(dir / "out.iso", kOld);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    signal(SIGXFSZ, SIG_IGN);
    rlimit limit{64 * 1024, 64 * 1024};
    setrlimit(RLIMIT_FSIZE, &limit);
    int status = 10;
    try {
      Writer writer(dir / "out.iso", FileHeader{});
      for (int i = 0; i < 100; ++i)
        writer.addChunk({.codec = Codec::Raw}, std::vector<std::byte>(8192));
      writer.finish();
    } catch (const FileError& error) {
      const std::string message = error.what();
      const bool namesFile = message.find((dir / "out.iso").string()) != std::string::npos;
      const bool saysWhy = message.find("cannot write") != std::string::npos;
      status = namesFile && saysWhy ? 0 : 11;
    } catch (...) {
      status = 12;
    }
    _exit(status);
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0)
      << "10: no error, 11: message lacks file or reason, 12: wrong type";
  EXPECT_EQ(test::readFile(dir / "out.iso"), kOld);
  EXPECT_EQ(listDirectory(dir.path()), std::vector<std::filesystem::path>{"out.iso"});
}

TEST(Writer, killedWriterLeavesNoAcceptableFileAtTheOutputPath) {
  test::TempDir dir;
  test::writeFile(dir / "out.iso", kOld);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    Writer writer(dir / "out.iso", FileHeader{});
    for (;;) writer.addChunk({.codec = Codec::Raw}, std::vector<std::byte>(4096, std::byte{7}));
  }
  // Wait until the child has written a good part of a file, then kill it without warning.
  std::filesystem::path temporary;
  for (int attempt = 0; attempt < 2000 && temporary.empty(); ++attempt) {
    for (const auto& e : std::filesystem::directory_iterator(dir.path()))
      if (e.path().extension() == ".isotmp" && e.file_size() > (1u << 20)) temporary = e.path();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_FALSE(temporary.empty()) << "the writer never got going";
  EXPECT_EQ(test::readFile(dir / "out.iso"), kOld);
  EXPECT_THROW(Reader::open(temporary), FileError);  // what it left has no trailer
}

TEST(Writer, rejectsInvalidHeadersAndChunks) {
  test::TempDir dir;
  FileHeader bad;
  bad.frame.size = 0;
  EXPECT_THROW(Writer(dir / "a.iso", bad), InternalError);
  bad = FileHeader{};
  bad.attributes.push_back({Semantic::Normal, Encoding::Srgb8, 3, 0});
  EXPECT_THROW(Writer(dir / "a.iso", bad), InternalError);
  bad = FileHeader{};
  bad.payloadAlignmentLog2 = 2;
  EXPECT_THROW(Writer(dir / "a.iso", bad), InternalError);
  EXPECT_TRUE(listDirectory(dir.path()).empty());

  FileHeader header;
  header.maxLevel = 2;
  Writer writer(dir / "a.iso", header);
  const std::vector<std::byte> data(10);
  EXPECT_THROW(writer.addChunk({.level = 3}, data), InternalError);
  EXPECT_THROW(writer.addChunk({.level = 1, .key = 8}, data), InternalError);
  EXPECT_THROW(writer.addChunk({.geometricError = -1.0f}, data), InternalError);
  EXPECT_THROW(writer.setMetadata("[1, 2]"), InternalError);
  const uint32_t root = writer.addChunk({}, data);
  const uint32_t child = writer.addChunk({.level = 1, .key = 3}, data);
  writer.setParent(root, child);  // a finer parent breaks the rules
  EXPECT_THROW(writer.finish(), InternalError);
  EXPECT_FALSE(std::filesystem::exists(dir / "a.iso"));
  writer.setParent(root, kNoParent);
  writer.setParent(child, root);
  writer.finish();
  EXPECT_EQ(Reader::open(dir / "a.iso").chunk(child).parent, root);
  EXPECT_THROW(writer.addChunk({}, data), InternalError);
}

// A file with a chunk of every kind and parent links of every sort (specs/iso-format.md, "Chunk
// table"): 0 a surface chunk at the root; 1 a surface chunk at level 1, child of 0; 2 a points
// chunk at level 1 whose parent 3 is its subsample at the root; 4 a values chunk; 5 a lighting
// chunk; 6 a zstd blob; 7 a surface chunk at level 2, child of 1.
FileHeader rulesHeader() {
  FileHeader header;
  header.maxLevel = 2;
  header.payloadAlignmentLog2 = 3;
  return header;
}

void writeRulesFile(const std::filesystem::path& path) {
  Writer writer(path, rulesHeader());
  const std::vector<std::byte> data(16, std::byte{3});
  writer.addChunk({.kind = kSurfaceKind,
                   .pointCount = 10,
                   .nodeCount = 1,
                   .leafCount = 1,
                   .geometricError = 0.5f,
                   .codec = Codec::Raw},
                  data);
  writer.addChunk({.kind = kSurfaceKind,
                   .level = 1,
                   .key = 5,
                   .parent = 0,
                   .pointCount = 4,
                   .codec = Codec::Raw},
                  data);
  writer.addChunk({.kind = kPointsKind,
                   .level = 1,
                   .key = 5,
                   .parent = 3,
                   .pointCount = 3,
                   .codec = Codec::Raw},
                  data);
  writer.addChunk({.kind = kPointsKind, .pointCount = 3, .codec = Codec::Raw}, data);
  writer.addChunk({.kind = kValuesKind, .level = 1, .key = 5, .pointCount = 3, .codec = Codec::Raw},
                  data);
  writer.addChunk({.kind = kLightingKind, .codec = Codec::Raw}, data);
  writer.addChunk({}, std::vector<std::byte>(4096));  // zstd
  writer.addChunk({.kind = kSurfaceKind,
                   .level = 2,
                   .key = 5 << 3 | 2,
                   .parent = 1,
                   .pointCount = 2,
                   .codec = Codec::Raw},
                  data);
  writer.finish();
}

TEST(Writer, refusesEveryEntryThatOpeningTheFileWouldReject) {
  test::TempDir dir;
  writeRulesFile(dir / "base.iso");
  const std::vector<std::byte> base = test::readFile(dir / "base.iso");
  const Reader reader = Reader::fromMemory(base, "base.iso");
  ASSERT_EQ(reader.chunks().size(), 8u);
  ASSERT_EQ(reader.chunk(6).codec, Codec::Zstd);
  const uint64_t zstdStored = reader.chunk(6).storedSize;

  struct Case {
    const char* rule;
    uint32_t chunk;
    std::function<void(ChunkInfo&)> change;
    const char* reason;
  };
  const float nan = std::nanf("");
  const std::vector<Case> cases = {
      {"unknown codec", 0, [](ChunkInfo& c) { c.codec = Codec(2); }, "unknown codec 2"},
      {"level above max", 0, [](ChunkInfo& c) { c.level = 3; }, "above the file's maximum level"},
      {"key out of range", 1, [](ChunkInfo& c) { c.key = 8; }, "key does not fit its level"},
      {"raw size over limit", 6, [](ChunkInfo& c) { c.rawSize = kMaxChunkRawSize + 1; },
       "over the limit of 2^30"},
      {"raw stored != raw", 0, [](ChunkInfo& c) { c.rawSize = 17; },
       "raw chunk with stored size != raw size"},
      {"zstd without bytes", 6, [](ChunkInfo& c) { c.storedSize = 0; },
       "zstd chunk with no stored bytes"},
      {"zstd ratio", 6, [&](ChunkInfo& c) { c.rawSize = zstdStored * kMaxZstdRatio + 1; },
       "more than 32768 times the stored size"},
      {"nan error", 0, [&](ChunkInfo& c) { c.geometricError = nan; }, "geometric error"},
      {"negative error", 0, [](ChunkInfo& c) { c.geometricError = -1.0f; }, "geometric error"},
      {"points without points", 3, [](ChunkInfo& c) { c.pointCount = 0; },
       "a points chunk holds 1 to 1048576 points, not 0"},
      {"points over the limit", 3, [](ChunkInfo& c) { c.pointCount = kMaxPointsPerChunk + 1; },
       "a points chunk holds 1 to 1048576 points, not 1048577"},
      {"points with nodes", 3, [](ChunkInfo& c) { c.nodeCount = 1; }, "a points chunk has nodes"},
      {"points with leaves", 2, [](ChunkInfo& c) { c.leafCount = 1; }, "a points chunk has leaves"},
      {"values with a parent", 4, [](ChunkInfo& c) { c.parent = 3; },
       "a values chunk of this kind has no parent"},
      {"lighting with points", 5, [](ChunkInfo& c) { c.pointCount = 1; },
       "a lighting chunk has points"},
      {"lighting with nodes", 5, [](ChunkInfo& c) { c.nodeCount = 1; },
       "a lighting chunk has nodes"},
      {"lighting with leaves", 5, [](ChunkInfo& c) { c.leafCount = 1; },
       "a lighting chunk has leaves"},
      {"lighting with a parent", 5, [](ChunkInfo& c) { c.parent = 0; },
       "a lighting chunk has no parent"},
      {"lighting with an error", 5, [](ChunkInfo& c) { c.geometricError = 1.0f; },
       "a lighting chunk has no geometric error"},
      {"missing parent", 1, [](ChunkInfo& c) { c.parent = 99; }, "parent 99 does not exist"},
      {"finer parent", 0, [](ChunkInfo& c) { c.parent = 1; },
       "parent 1 is not a coarser cell containing it"},
      {"parent that does not contain", 7, [](ChunkInfo& c) { c.key = 6 << 3; },
       "parent 1 is not a coarser cell containing it"},
      {"points under a surface", 2, [](ChunkInfo& c) { c.parent = 0; },
       "parent 0 is not a points chunk"},
      {"more points than the parent", 1, [](ChunkInfo& c) { c.pointCount = 11; },
       "point count 11 and those of the other chunks of parent 0 exceed its 10"},
      {"top counts over 2^53", 0, [](ChunkInfo& c) { c.pointCount = kMaxPointCount + 1; },
       "brings the points of the top surface chunks over 2^53"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.rule);
    std::vector<ChunkInfo> entries(reader.chunks().begin(), reader.chunks().end());
    c.change(entries[c.chunk]);

    // Opening refuses the file with this entry.
    const std::vector<std::byte> changed = test::withChangedEntry(base, c.chunk, c.change);
    std::string readerReason;
    try {
      Reader::fromMemory(changed, "changed.iso");
      ADD_FAILURE() << "the reader opened it";
    } catch (const FileError& error) {
      readerReason = error.reason();
    }
    EXPECT_NE(readerReason.find("chunk " + std::to_string(c.chunk) + ": "), std::string::npos)
        << readerReason;
    EXPECT_NE(readerReason.find(c.reason), std::string::npos) << readerReason;

    // The writer refuses to write it, with the reader's reason, and writes nothing.
    std::string writerMessage;
    try {
      Writer writer(dir / "out.iso", rulesHeader());
      for (const ChunkInfo& e : entries) {
        const ChunkInfo& original = reader.chunk(e.id);
        writer.copyChunk(e, reader.bytes().subspan(original.offset, original.storedSize));
      }
      writer.finish();
      ADD_FAILURE() << "the writer wrote it";
    } catch (const InternalError& error) {
      writerMessage = error.what();
    }
    EXPECT_NE(writerMessage.find(readerReason), std::string::npos)
        << writerMessage << "\nthe reader: " << readerReason;
    EXPECT_FALSE(std::filesystem::exists(dir / "out.iso"));
    EXPECT_EQ(listDirectory(dir.path()), std::vector<std::filesystem::path>{"base.iso"});
  }

  // The same entries once more as the writer is given them: a description, and a parent set
  // later.
  Writer writer(dir / "out.iso", rulesHeader());
  const std::vector<std::byte> data(16);
  try {
    writer.addChunk({.kind = kValuesKind, .codec = Codec::Raw}, data);
    ADD_FAILURE() << "a values chunk without values was written";
  } catch (const InternalError& error) {
    EXPECT_NE(std::string(error.what()).find("chunk 0: a values chunk holds 1 to"),
              std::string::npos)
        << error.what();
  }
  EXPECT_EQ(writer.chunkCount(), 0u);
  EXPECT_THROW(writer.addChunk({.kind = kLightingKind, .geometricError = 1.0f}, data),
               InternalError);
  const uint32_t points = writer.addChunk({.kind = kPointsKind, .pointCount = 2}, data);
  const uint32_t values = writer.addChunk({.kind = kValuesKind, .pointCount = 2}, data);
  EXPECT_THROW(writer.setParent(values, points), InternalError);
  writer.finish();
  EXPECT_EQ(Reader::open(dir / "out.iso").chunk(values).parent, kNoParent);
}

TEST(Writer, outputInMissingDirectoryIsAClearError) {
  test::TempDir dir;
  try {
    Writer writer(dir / "no-such-dir" / "a.iso", FileHeader{});
    ADD_FAILURE();
  } catch (const FileError& error) {
    EXPECT_NE(std::string(error.what()).find("a.iso"), std::string::npos);
    EXPECT_NE(error.reason().find("No such file or directory"), std::string::npos);
  }
}

}  // namespace
}  // namespace iso

namespace iso {
namespace {

TEST(Writer, closedFileCanBeReadThenItsMetadataReplacedBeforeCommit) {
  test::TempDir dir;
  Writer writer(dir / "out.iso", FileHeader{});
  writer.addChunk({}, std::vector<std::byte>(3000, std::byte{9}));
  writer.setMetadata(R"({"step":1})");
  writer.close();
  EXPECT_FALSE(std::filesystem::exists(dir / "out.iso"));
  EXPECT_EQ(Reader::open(writer.temporaryPath()).metadata(), R"({"step":1})");
  writer.replaceMetadata(R"({"step":2,"longer":"metadata than before"})");
  writer.replaceMetadata(R"({"step":3})");  // shorter again
  writer.commit();
  const Reader reader = Reader::open(dir / "out.iso");
  EXPECT_EQ(reader.metadata(), R"({"step":3})");
  EXPECT_EQ(reader.chunks().size(), 1u);
  EXPECT_TRUE(verifyFile(reader).ok());
  EXPECT_EQ(listDirectory(dir.path()), std::vector<std::filesystem::path>{"out.iso"});
}

}  // namespace
}  // namespace iso
