// The writer never leaves an acceptable file at the output path unless it finished, never harms a
// file already there, reports failed writes (a full disk) with the file name, and rejects invalid
// chunk descriptions.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/reader.h"
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
