// The files a run makes (base/files.h): outputs checked before any work, written all or none, and
// directories made for temporary files and removed again.
#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "iso/error.h"
#include "pipeline/base/files.h"
#include "tests/support/support.h"

namespace iso {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void put(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

// The names in a directory, sorted.
std::vector<std::string> entries(const fs::path& directory) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(directory))
    names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// The reason of the FileError that f throws, and its file; empty when it throws none.
std::pair<std::string, std::string> fileErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const FileError& error) {
    return {error.file(), error.reason()};
  }
  return {};
}

TEST(OutputGroup, commitPutsEveryOutputInPlaceAndLeavesNoTemporaryName) {
  test::TempDir dir;
  put(dir / "a.ply", "old a");
  {
    OutputGroup group;
    put(group.stage(dir / "a.ply"), "new a");
    put(group.stage(dir / "b.vdb"), "new b");
    EXPECT_EQ(slurp(dir / "a.ply"), "old a");  // nothing in place before commit()
    EXPECT_FALSE(fs::exists(dir / "b.vdb"));
    group.commit();
  }
  EXPECT_EQ(slurp(dir / "a.ply"), "new a");
  EXPECT_EQ(slurp(dir / "b.vdb"), "new b");
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"a.ply", "b.vdb"}));
}

TEST(OutputGroup, aGroupNotCommittedLeavesNothingNew) {
  test::TempDir dir;
  put(dir / "a.ply", "old a");
  {
    OutputGroup group;
    put(group.stage(dir / "a.ply"), "new a");
    put(group.stage(dir / "b.vdb"), "new b");
  }  // a later output failed: the group is dropped
  EXPECT_EQ(slurp(dir / "a.ply"), "old a");
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"a.ply"}));
}

TEST(OutputGroup, aRenameThatFailsUndoesTheOnesBeforeIt) {
  test::TempDir dir;
  put(dir / "a.ply", "old a");
  fs::create_directory(dir / "c");  // a directory with a file in it: no rename can replace it
  put(dir / "c" / "keep", "mine");
  OutputGroup group;
  put(group.stage(dir / "a.ply"), "new a");
  put(group.stage(dir / "b.ply"), "new b");
  put(group.stage(dir / "c"), "new c");
  const auto [file, reason] = fileErrorOf([&] { group.commit(); });
  EXPECT_EQ(file, (dir / "c").string());
  EXPECT_NE(reason.find("no output was written"), std::string::npos) << reason;
  EXPECT_EQ(slurp(dir / "a.ply"), "old a");  // put back
  EXPECT_FALSE(fs::exists(dir / "b.ply"));   // taken away again
  EXPECT_EQ(slurp(dir / "c" / "keep"), "mine");
  EXPECT_EQ(entries(dir.path()).size(), 3u);  // a.ply, c and c's staged file, until the group goes
}

TEST(OutputGroup, nothingOfAFailedGroupOutlivesIt) {
  test::TempDir dir;
  fs::create_directory(dir / "c");
  put(dir / "c" / "keep", "mine");
  {
    OutputGroup group;
    put(group.stage(dir / "a.ply"), "new a");
    put(group.stage(dir / "c"), "new c");
    EXPECT_THROW(group.commit(), FileError);
  }
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"c"}));
}

TEST(OutputPath, theMissingOrWrongDirectoryIsNamed) {
  test::TempDir dir;
  put(dir / "file", "x");
  auto [file, reason] =
      fileErrorOf([&] { checkOutputPath(dir / "no" / "such" / "o.iso", "-o", false); });
  EXPECT_EQ(file, (dir / "no" / "such" / "o.iso").string());
  EXPECT_EQ(reason, "the directory " + (dir / "no" / "such").string() + " does not exist");
  std::tie(file, reason) =
      fileErrorOf([&] { checkOutputPath(dir / "file" / "o.iso", "-o", false); });
  EXPECT_EQ(reason, (dir / "file").string() + " is not a directory");
  std::tie(file, reason) =
      fileErrorOf([&] { checkOutputPath(dir / "file" / "deeper" / "o.iso", "-o", false); });
  EXPECT_EQ(reason, (dir / "file").string() + " is not a directory");
}

TEST(OutputPath, directoriesExistingFilesAndInputsAreRefused) {
  test::TempDir dir;
  put(dir / "in.ply", "x");
  fs::create_directory(dir / "sub");
  auto [file, reason] = fileErrorOf([&] { checkOutputPath(dir / "sub", "--mesh", true); });
  EXPECT_EQ(reason, "is a directory (--mesh wants a file name)");
  std::tie(file, reason) = fileErrorOf([&] { checkOutputPath(dir / "in.ply", "-o", false); });
  EXPECT_EQ(reason, "exists already (use --force to replace it)");
  EXPECT_NO_THROW(checkOutputPath(dir / "in.ply", "-o", true));
  EXPECT_NO_THROW(checkOutputPath(dir / "new.ply", "-o", false));
  fs::create_symlink(dir / "in.ply", dir / "link.ply");
  std::tie(file, reason) =
      fileErrorOf([&] { refuseOutputOverInput(dir / "link.ply", dir / "in.ply", "-o"); });
  EXPECT_EQ(reason, "is also an input (-o would replace " + (dir / "in.ply").string() + ")");
  EXPECT_NO_THROW(refuseOutputOverInput(dir / "new.ply", dir / "in.ply", "-o"));
}

TEST(OutputPath, twoNamesOfOneFileAreTheSameFileWhetherItExistsOrNot) {
  test::TempDir dir;
  fs::create_directory(dir / "sub");
  EXPECT_TRUE(namesSameFile(dir / "new.ply", dir / "sub" / ".." / "new.ply"));
  EXPECT_TRUE(namesSameFile(dir / "new.ply", dir / "." / "new.ply"));
  EXPECT_FALSE(namesSameFile(dir / "new.ply", dir / "sub" / "new.ply"));
  put(dir / "old.ply", "x");
  fs::create_symlink(dir / "old.ply", dir / "sub" / "link.ply");
  EXPECT_TRUE(namesSameFile(dir / "old.ply", dir / "sub" / "link.ply"));
  fs::create_directory_symlink(dir / "sub", dir / "alias");
  EXPECT_TRUE(namesSameFile(dir / "sub" / "new.ply", dir / "alias" / "new.ply"));
  EXPECT_FALSE(namesSameFile(dir / "old.ply", dir / "new.ply"));
}

TEST(OutputPath, aDirectoryThatCannotBeWrittenInIsRefused) {
  test::TempDir dir;
  test::ReadOnlyDirectory locked(dir / "locked");
  if (!locked.ok()) GTEST_SKIP() << "cannot make a read-only directory here";
  locked.lock();
  const auto [file, reason] =
      fileErrorOf([&] { checkOutputPath(dir / "locked" / "o.iso", "-o", true); });
  EXPECT_EQ(reason.rfind("cannot write in the directory " + (dir / "locked").string() + ": ", 0),
            0u)
      << reason;
}

TEST(MadeDirectories, missingDirectoriesAreMadeAndRemovedDeepestFirst) {
  test::TempDir dir;
  fs::create_directory(dir / "had");
  {
    MadeDirectories made(dir / "had" / "a" / "b" / "c", "--tmp");
    EXPECT_TRUE(fs::is_directory(dir / "had" / "a" / "b" / "c"));
    EXPECT_EQ(made.made(), (std::vector<fs::path>{dir / "had" / "a", dir / "had" / "a" / "b",
                                                  dir / "had" / "a" / "b" / "c"}));
  }
  EXPECT_EQ(entries(dir / "had"), std::vector<std::string>{});  // "had" was there before
  {
    MadeDirectories made(dir / "had", "--tmp");  // nothing to make, nothing to remove
    EXPECT_TRUE(made.made().empty());
  }
  EXPECT_TRUE(fs::is_directory(dir / "had"));
}

TEST(MadeDirectories, aDirectoryThatHoldsSomethingIsKept) {
  test::TempDir dir;
  {
    MadeDirectories made(dir / "a" / "b", "--tmp");
    put(dir / "a" / "b" / "someone's", "x");
  }
  EXPECT_EQ(slurp(dir / "a" / "b" / "someone's"), "x");
}

TEST(MadeDirectories, whatCannotBeMadeIsNamed) {
  test::TempDir dir;
  put(dir / "file", "x");
  auto [file, reason] = fileErrorOf([&] { MadeDirectories made(dir / "file" / "t", "--tmp"); });
  EXPECT_EQ(file, (dir / "file").string());
  EXPECT_EQ(reason, "is not a directory (--tmp)");
  test::ReadOnlyDirectory locked(dir / "locked");
  if (!locked.ok()) GTEST_SKIP() << "cannot make a read-only directory here";
  locked.lock();
  std::tie(file, reason) =
      fileErrorOf([&] { MadeDirectories made(dir / "locked" / "a" / "b", "--tmp"); });
  EXPECT_EQ(file, (dir / "locked" / "a").string());
  EXPECT_EQ(reason.rfind("cannot make this directory for --tmp " +
                             (dir / "locked" / "a" / "b").string() + ": ",
                         0),
            0u)
      << reason;
}

// Of many threads claiming the same pieces, exactly one gets each; a directory that is not there
// is named in the error.
TEST(ClaimFile, exactlyOneClaimantGetsEachPiece) {
  test::TempDir dir;
  constexpr int kPieces = 64, kClaimants = 4;
  std::vector<std::atomic<int>> got(kPieces);
  std::vector<std::thread> claimants;
  for (int t = 0; t < kClaimants; ++t)
    claimants.emplace_back([&] {
      for (int p = 0; p < kPieces; ++p)
        if (claimFile(dir / ("claim-" + std::to_string(p)))) ++got[size_t(p)];
    });
  for (std::thread& t : claimants) t.join();
  for (int p = 0; p < kPieces; ++p) EXPECT_EQ(got[size_t(p)].load(), 1) << p;
  EXPECT_FALSE(claimFile(dir / "claim-0"));
  const auto [file, reason] = fileErrorOf([&] { claimFile(dir / "no" / "claim-0"); });
  EXPECT_EQ(file, (dir / "no" / "claim-0").string());
  EXPECT_NE(reason.find("cannot claim"), std::string::npos) << reason;
}

}  // namespace
}  // namespace iso
