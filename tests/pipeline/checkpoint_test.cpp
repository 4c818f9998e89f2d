// Checkpoints of a resumable run (base/checkpoint.h): what is written is read back exactly, and a
// file that is cut, damaged, of another run or read in another order is refused, never used.
#include <gtest/gtest.h>

#include <fstream>
#include <numeric>
#include <vector>

#include "pipeline/base/checkpoint.h"
#include "tests/support/support.h"

namespace iso {
namespace {

namespace fs = std::filesystem;

std::vector<double> numbers(size_t n) {
  std::vector<double> v(n);
  std::iota(v.begin(), v.end(), 0.25);
  return v;
}

void write(const fs::path& path, const std::string& fingerprint) {
  fs::remove(path);
  CheckpointWriter out(path, fingerprint);
  out.json("meta", {{"points", 3}});
  out.array("values", numbers(3'000'000));  // more than the writer's buffer
  out.array("empty", std::vector<int>{});
  EXPECT_FALSE(fs::exists(path));  // only once whole
  const uint64_t written = out.commit();
  EXPECT_EQ(written, fs::file_size(path));
}

TEST(Checkpoint, readsBackWhatWasWritten) {
  test::TempDir dir;
  write(dir / "c", "run 1");
  CheckpointReader in(dir / "c", "run 1");
  EXPECT_EQ(in.json("meta")["points"], 3);
  std::vector<double> values;
  in.array("values", values);
  EXPECT_EQ(values, numbers(3'000'000));
  std::vector<int> empty{1};
  in.array("empty", empty);
  EXPECT_TRUE(empty.empty());
  in.finish();
}

TEST(Checkpoint, appendsASectionAfterTheValuesAlreadyThere) {
  test::TempDir dir;
  write(dir / "c", "run 1");
  CheckpointReader in(dir / "c", "run 1");
  in.json("meta");
  std::vector<double> values = {-1.0, -2.0};
  in.appendArray("values", values);
  std::vector<double> expected = {-1.0, -2.0};
  const std::vector<double> read = numbers(3'000'000);
  expected.insert(expected.end(), read.begin(), read.end());
  EXPECT_EQ(values, expected);
  std::vector<int> kept{7};
  in.appendArray("empty", kept);
  EXPECT_EQ(kept, std::vector<int>{7});
  in.finish();
}

TEST(Checkpoint, refusesWhatIsCutDamagedForeignOrReadOutOfOrder) {
  test::TempDir dir;
  write(dir / "c", "run 1");
  EXPECT_THROW(CheckpointReader(dir / "c", "run 2"), CheckpointError);
  {
    CheckpointReader in(dir / "c", "run 1");
    std::vector<double> values;
    EXPECT_THROW(in.array("values", values), CheckpointError);  // "meta" comes first
  }
  const auto readAll = [&] {
    CheckpointReader in(dir / "c", "run 1");
    in.json("meta");
    std::vector<double> values;
    in.array("values", values);
    std::vector<int> empty;
    in.array("empty", empty);
    in.finish();
  };
  const uintmax_t size = fs::file_size(dir / "c");
  {
    std::fstream f(dir / "c", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(size / 2));
    const char flipped = char(f.peek() ^ 1);
    f.put(flipped);
  }
  EXPECT_THROW(readAll(), CheckpointError);
  write(dir / "c", "run 1");
  fs::resize_file(dir / "c", size - 9);
  EXPECT_THROW(readAll(), CheckpointError);
}

TEST(Checkpoint, aWriterNotCommittedLeavesNothing) {
  test::TempDir dir;
  { CheckpointWriter(dir / "c", "run").array("values", numbers(1000)); }
  EXPECT_TRUE(fs::is_empty(dir.path()));
}

TEST(Checkpoint, theStateOfAnotherRunIsRemovedWhole) {
  test::TempDir dir;
  write(ResumeState(dir / "state", "run 0").path("a"), "run 0");
  ResumeState again(dir / "state", "run 0");
  EXPECT_TRUE(again.has("a"));
  EXPECT_TRUE(again.notes().empty());
  ResumeState other(dir / "state", "run 1");
  EXPECT_FALSE(other.has("a"));
  ASSERT_EQ(other.notes().size(), 1u);
  EXPECT_NE(other.notes()[0].find("of another conversion"), std::string::npos);
}

TEST(Checkpoint, theStateSetsAsideACheckpointItCannotUse) {
  test::TempDir dir;
  ResumeState state(dir / "state", "run 1");
  write(state.path("a"), "run 0");  // as if made by another run
  EXPECT_TRUE(state.has("a"));
  EXPECT_EQ(state.open("a"), nullptr);
  EXPECT_FALSE(state.has("a"));
  ASSERT_EQ(state.notes().size(), 1u);
  EXPECT_NE(state.notes()[0].find("another conversion"), std::string::npos);
  write(state.path("b"), "run 1");
  EXPECT_NE(state.open("b"), nullptr);
  state.finish();
  EXPECT_FALSE(fs::exists(dir / "state"));
}

}  // namespace
}  // namespace iso
