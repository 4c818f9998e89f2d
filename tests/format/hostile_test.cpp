// Malformed, truncated and hostile files: every one is rejected with the file, the offset and the
// reason, or caught by verification; none crashes (these tests also run under ASan and UBSan).
#include <gtest/gtest.h>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cmath>
#include <cstring>
#include <functional>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/verify.h"
#include "tests/support/support.h"

namespace iso {
namespace {

const std::filesystem::path kGolden = std::filesystem::path(ISO_TEST_DATA_DIR) / "golden-v1.iso";

// Opening bytes either fails with a FileError or verification reports a problem.
bool isRejectedOrCaught(const std::vector<std::byte>& bytes) {
  try {
    const Reader reader = Reader::fromMemory(bytes, "mutant.iso");
    return !verifyFile(reader).ok();
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), "mutant.iso");
    EXPECT_FALSE(error.reason().empty());
    return true;
  }
}

// The FileError that opening bytes throws; fails the test when it opens.
FileError openError(const std::vector<std::byte>& bytes) {
  try {
    Reader::fromMemory(bytes, "hostile.iso");
  } catch (const FileError& error) {
    return error;
  }
  ADD_FAILURE() << "file was accepted";
  return FileError("", std::nullopt, "");
}

template <typename T>
void put(std::vector<std::byte>& b, size_t offset, T value) {
  std::memcpy(b.data() + offset, &value, sizeof(T));
}

template <typename T>
T get(const std::vector<std::byte>& b, size_t offset) {
  T value;
  std::memcpy(&value, b.data() + offset, sizeof(T));
  return value;
}

class Hostile : public ::testing::Test {
 protected:
  void SetUp() override {
    golden_ = test::readFile(kGolden);
    trailer_ = golden_.size() - 64;
    table_ = get<uint64_t>(golden_, trailer_);
  }
  // The golden file with a change applied and all checksums recomputed.
  std::vector<std::byte> mutate(const std::function<void(std::vector<std::byte>&)>& change) {
    std::vector<std::byte> b = golden_;
    change(b);
    test::resealChecksums(b);
    return b;
  }
  size_t entry(uint32_t i) const { return table_ + 80 * i; }

  std::vector<std::byte> golden_;
  size_t trailer_ = 0, table_ = 0;
};

TEST_F(Hostile, everyTruncatedPrefixIsRejected) {
  for (size_t size = 0; size < golden_.size(); ++size) {
    const std::vector<std::byte> prefix(golden_.begin(), golden_.begin() + ptrdiff_t(size));
    EXPECT_THROW(Reader::fromMemory(prefix, "prefix.iso"), FileError)
        << "prefix of " << size << " bytes";
  }
}

TEST_F(Hostile, truncationNamesTheProblem) {
  const std::vector<std::byte> prefix(golden_.begin(), golden_.end() - 1);
  const FileError error = openError(prefix);
  EXPECT_EQ(error.offset(), prefix.size() - 64 + 56);
  EXPECT_NE(error.reason().find("truncated"), std::string::npos) << error.what();
  const std::vector<std::byte> tiny(golden_.begin(), golden_.begin() + 100);
  EXPECT_NE(std::string(openError(tiny).what()).find("too small"), std::string::npos);
}

TEST_F(Hostile, everySingleByteChangeIsRejectedOrCaughtByVerify) {
  for (uint8_t mask : {0x01, 0x80, 0xFF}) {
    for (size_t i = 0; i < golden_.size(); ++i) {
      std::vector<std::byte> b = golden_;
      b[i] ^= std::byte{mask};
      ASSERT_TRUE(isRejectedOrCaught(b))
          << "byte " << i << " xor " << int(mask) << " went unnoticed";
    }
  }
}

TEST_F(Hostile, surfaceChunkCountsThatDisagreeWithTheTableAreRejected) {
  // Chunk 5 of the golden file is a surface of 3 nodes; its table entry says so.
  for (const auto& [field, value] : {std::pair{56, 4u}, std::pair{60, 7u}}) {
    std::vector<std::byte> b = golden_;
    put<uint32_t>(b, entry(5) + field, value);
    test::resealChecksums(b);
    const Reader reader = Reader::fromMemory(b, "counts.iso");
    try {
      decodeSurfaceChunk(reader, 5);
      ADD_FAILURE() << "accepted a table count of " << value << " at byte " << field;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find("the chunk table gives"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(verifyFile(reader).ok());
  }
}

TEST_F(Hostile, payloadChangeIsCaughtByVerifyAndNamesTheChunk) {
  std::vector<std::byte> b = golden_;
  const uint64_t payload = get<uint64_t>(b, entry(1));
  b[payload + 10] ^= std::byte{0x40};
  const Reader reader = Reader::fromMemory(b, "flip.iso");  // payloads are not read at open
  const VerifyResult result = verifyFile(reader);
  ASSERT_EQ(result.problems.size(), 1u);
  EXPECT_EQ(result.problems[0].chunk, 1u);
  EXPECT_EQ(result.problems[0].offset, payload);
  EXPECT_NE(describe(reader, result.problems[0]).find("chunk 1 (level 1, key 0x5)"),
            std::string::npos);
  EXPECT_NE(result.problems[0].reason.find("checksum mismatch"), std::string::npos);
}

TEST_F(Hostile, checksumsGuardEachStructure) {
  auto flip = [&](size_t offset) {
    std::vector<std::byte> b = golden_;
    b[offset] ^= std::byte{1};
    return std::string(openError(b).reason());
  };
  EXPECT_NE(flip(30).find("header checksum"), std::string::npos);
  EXPECT_NE(flip(table_ + 3).find("chunk table checksum"), std::string::npos);
  EXPECT_NE(flip(trailer_ - 3).find("metadata checksum"), std::string::npos);
  EXPECT_NE(flip(trailer_ + 20).find("trailer checksum"), std::string::npos);
  EXPECT_NE(flip(1).find("magic"), std::string::npos);
}

TEST_F(Hostile, structuralRulesAreCheckedBehindValidChecksums) {
  struct Case {
    const char* name;
    std::function<void(std::vector<std::byte>&)> change;
    const char* reason;
    std::function<uint64_t()> offset;
  };
  const std::vector<Case> cases = {
      {"major version", [](auto& b) { put<uint16_t>(b, 8, 2); }, "not supported", [] { return 8; }},
      {"header size", [](auto& b) { put<uint32_t>(b, 12, 512); }, "header size", [] { return 12; }},
      {"reserved flag", [](auto& b) { put<uint32_t>(b, 16, 1); }, "reserved flag",
       [] { return 16; }},
      {"unused flag is fine", [](auto&) {}, nullptr, nullptr},
      {"reserved header byte", [](auto& b) { b[23] = std::byte{1}; }, "reserved",
       [] { return 23; }},
      {"reserved header tail", [](auto& b) { b[200] = std::byte{1}; }, "reserved",
       [] { return 120; }},
      {"alignment", [](auto& b) { b[20] = std::byte{17}; }, "alignment", [] { return 20; }},
      {"max level", [](auto& b) { b[21] = std::byte{22}; }, "over 21", [] { return 21; }},
      {"attribute count", [](auto& b) { b[22] = std::byte{0}; }, "attribute count",
       [] { return 22; }},
      {"nan origin", [](auto& b) { put<double>(b, 32, std::nan("")); }, "origin",
       [] { return 32; }},
      {"zero frame", [](auto& b) { put<double>(b, 48, 0.0); }, "frame size", [] { return 48; }},
      {"infinite frame", [](auto& b) { put<double>(b, 48, INFINITY); }, "frame size",
       [] { return 48; }},
      {"duplicate semantic", [](auto& b) { b[64] = std::byte{1}; }, "twice", [] { return 56; }},
      {"bad encoding", [](auto& b) { b[65] = std::byte{5}; }, "not allowed", [] { return 56; }},
      {"unknown encoding", [](auto& b) { b[65] = std::byte{99}; }, "unknown attribute encoding",
       [] { return 56; }},
      {"negative distance scale", [](auto& b) { put<float>(b, 60, -1.0f); }, "scale",
       [] { return 56; }},
      {"unused attribute slot", [](auto& b) { b[80] = std::byte{1}; }, "unused attribute",
       [] { return 80; }},
      {"entry size", [this](auto& b) { put<uint32_t>(b, trailer_ + 12, 96); }, "entry size",
       [this] { return trailer_ + 12; }},
      {"huge chunk count", [this](auto& b) { put<uint32_t>(b, trailer_ + 8, 0xFFFFFFFFu); },
       "does not fit", [this] { return trailer_ + 16; }},
      {"table offset past end", [this](auto& b) { put<uint64_t>(b, trailer_, ~uint64_t{0} - 7); },
       "chunk table offset", [this] { return trailer_; }},
      {"table offset unaligned", [this](auto& b) { put<uint64_t>(b, trailer_, table_ - 8); },
       "not aligned", [this] { return trailer_; }},
      {"metadata size", [this](auto& b) { put<uint64_t>(b, trailer_ + 24, 1); }, "metadata size",
       [this] { return trailer_ + 24; }},
      {"entry id", [this](auto& b) { put<uint32_t>(b, entry(2) + 48, 7); }, "id is 7",
       [this] { return entry(2) + 48; }},
      {"entry reserved byte", [this](auto& b) { b[entry(1) + 71] = std::byte{1}; }, "reserved",
       [this] { return entry(1) + 71; }},
      {"entry reserved tail", [this](auto& b) { b[entry(1) + 79] = std::byte{1}; }, "reserved",
       [this] { return entry(1) + 72; }},
      {"unknown codec", [this](auto& b) { b[entry(0) + 69] = std::byte{2}; }, "unknown codec",
       [this] { return entry(0) + 69; }},
      {"level above max", [this](auto& b) { b[entry(1) + 68] = std::byte{4}; },
       "above the file's maximum", [this] { return entry(1) + 68; }},
      {"key out of range", [this](auto& b) { put<uint64_t>(b, entry(1) + 32, 8); }, "key",
       [this] { return entry(1) + 32; }},
      {"raw size over limit",
       [this](auto& b) { put<uint64_t>(b, entry(0) + 16, uint64_t{1} << 31); }, "limit",
       [this] { return entry(0) + 16; }},
      {"raw stored != raw", [this](auto& b) { put<uint64_t>(b, entry(1) + 16, 301); },
       "stored size", [this] { return entry(1) + 8; }},
      {"misplaced payload", [this](auto& b) { put<uint64_t>(b, entry(1), 4096 * 3); }, "layout",
       [this] { return entry(1); }},
      {"payload overlapping table",
       [this](auto& b) {
         put<uint64_t>(b, entry(5) + 8, ~uint64_t{0});
         put<uint64_t>(b, entry(5) + 16, ~uint64_t{0});
       },
       "limit", [this] { return entry(5) + 16; }},
      {"payload into table",
       [this](auto& b) {
         put<uint64_t>(b, entry(5) + 8, 5000);
         put<uint64_t>(b, entry(5) + 16, 5000);
       },
       "runs into the chunk table", [this] { return entry(5) + 8; }},
      {"nan error", [this](auto& b) { put<float>(b, entry(0) + 64, std::nanf("")); },
       "geometric error", [this] { return entry(0) + 64; }},
      {"negative error", [this](auto& b) { put<float>(b, entry(0) + 64, -1.0f); },
       "geometric error", [this] { return entry(0) + 64; }},
      {"missing parent", [this](auto& b) { put<uint32_t>(b, entry(1) + 52, 6); }, "does not exist",
       [this] { return entry(1) + 52; }},
      {"parent not coarser", [this](auto& b) { put<uint32_t>(b, entry(1) + 52, 3); }, "coarser",
       [this] { return entry(1) + 52; }},
      {"parent cycle", [this](auto& b) { put<uint32_t>(b, entry(0) + 52, 1); }, "coarser",
       [this] { return entry(0) + 52; }},
      {"parent does not contain", [this](auto& b) { put<uint64_t>(b, entry(2) + 32, 3); },
       "coarser", [this] { return entry(2) + 52; }},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::vector<std::byte> b = mutate(c.change);
    if (c.reason == nullptr) {
      EXPECT_NO_THROW(Reader::fromMemory(b, "ok.iso"));
      continue;
    }
    const FileError error = openError(b);
    EXPECT_NE(error.reason().find(c.reason), std::string::npos) << error.what();
    EXPECT_EQ(error.offset(), c.offset()) << error.what();
    EXPECT_EQ(error.file(), "hostile.iso");
  }
}

TEST_F(Hostile, unusedFlagBitsAreIgnored) {
  const std::vector<std::byte> b =
      mutate([](auto& bytes) { put<uint32_t>(bytes, 16, 0x00010000u); });
  EXPECT_EQ(Reader::fromMemory(b, "flags.iso").header().flags, 0x00010000u);
}

TEST_F(Hostile, newerMinorVersionIsRead) {
  const std::vector<std::byte> b = mutate([](auto& bytes) { put<uint16_t>(bytes, 10, 7); });
  EXPECT_EQ(Reader::fromMemory(b, "minor.iso").header().versionMinor, 7);
}

TEST_F(Hostile, corruptZstdStreamsFailToDecodeWithoutCrashing) {
  // Lie about the raw size: the frame's content size no longer matches.
  std::vector<std::byte> b =
      mutate([this](auto& bytes) { put<uint64_t>(bytes, entry(0) + 16, 1999); });
  const Reader reader = Reader::fromMemory(b, "zstd.iso");
  std::vector<std::byte> out(4000);
  try {
    reader.decodePayload(0, out);
    ADD_FAILURE() << "decoded";
  } catch (const FileError& error) {
    EXPECT_NE(error.reason().find("chunk 0"), std::string::npos);
    EXPECT_EQ(error.offset(), 4096u);
  }
  const VerifyResult result = verifyFile(reader);
  ASSERT_EQ(result.problems.size(), 1u);
  EXPECT_EQ(result.problems[0].chunk, 0u);
  EXPECT_NE(result.problems[0].reason.find("content size"), std::string::npos);

  // Damage the frame itself and fix its checksum: decoding reports it.
  std::vector<std::byte> damaged = golden_;
  for (size_t i = 4096 + 6; i < 4096 + 40; ++i) damaged[i] ^= std::byte{0x5A};
  const uint64_t stored = get<uint64_t>(damaged, entry(0) + 8);
  put<uint64_t>(damaged, entry(0) + 24, XXH3_64bits(damaged.data() + 4096, stored));
  test::resealChecksums(damaged);
  const Reader damagedReader = Reader::fromMemory(damaged, "zstd.iso");
  EXPECT_THROW(damagedReader.decodePayload(0, out), FileError);
  EXPECT_FALSE(verifyFile(damagedReader).ok());
}

TEST(HostileFiles, notAnIsoFileIsNamed) {
  test::TempDir dir;
  std::vector<std::byte> text(4000, std::byte{'a'});
  test::writeFile(dir / "text.iso", text);
  try {
    Reader::open(dir / "text.iso");
    ADD_FAILURE();
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), (dir / "text.iso").string());
    EXPECT_NE(error.reason().find("not an .iso file"), std::string::npos);
  }
  EXPECT_THROW(Reader::open(dir / "missing.iso"), FileError);
  EXPECT_THROW(Reader::open(dir.path()), FileError);  // a directory
  test::writeFile(dir / "empty.iso", {});
  EXPECT_THROW(Reader::open(dir / "empty.iso"), FileError);
}

}  // namespace
}  // namespace iso
