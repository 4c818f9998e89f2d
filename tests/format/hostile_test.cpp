// Malformed, truncated and hostile files: every one is rejected with the file, the offset and the
// reason, or caught by verification; none crashes (these tests also run under ASan and UBSan). No
// way to a chunk's data gives damaged data, and none allocates more than the payload can hold.
#include <gtest/gtest.h>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <new>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/points.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/surface_model.h"
#include "iso/verify.h"
#include "iso/writer.h"
#include "tests/support/support.h"

namespace iso::test {
// The largest single request to operator new (below) since a test last set it to 0.
std::atomic<size_t> largestAllocation{0};
}  // namespace iso::test

// The test program's operator new, which records the largest request: how a test sees that a
// reader refused a hostile size before allocating it. (operator new[] and the nothrow forms call
// this one.)
void* operator new(std::size_t size) {
  size_t seen = iso::test::largestAllocation.load(std::memory_order_relaxed);
  while (size > seen && !iso::test::largestAllocation.compare_exchange_weak(
                            seen, size, std::memory_order_relaxed)) {
  }
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
// GCC warns that free() meets memory from operator new wherever it inlines these: here that is
// the design.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

namespace iso {
namespace {

const std::filesystem::path kGolden = std::filesystem::path(ISO_TEST_DATA_DIR) / "golden-v2.iso";

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
      {"major version", [](auto& b) { put<uint16_t>(b, 8, 3); }, "not supported", [] { return 8; }},
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

// Calls body and expects the FileError of a checksum mismatch in chunk id, at its payload.
void expectChecksumMismatch(const char* what, const std::function<void()>& body,
                            const std::string& file, uint32_t id, uint64_t offset) {
  SCOPED_TRACE(what);
  try {
    body();
    ADD_FAILURE() << "accepted damaged data";
  } catch (const FileError& error) {
    EXPECT_EQ(error.file(), file);
    EXPECT_EQ(error.offset(), offset);
    EXPECT_NE(error.reason().find("chunk " + std::to_string(id) + ": checksum mismatch"),
              std::string::npos)
        << error.what();
  }
}

TEST_F(Hostile, everyWayToAChunksDataRefusesAFlippedPayloadByte) {
  for (uint32_t id : {0u, 1u, 2u, 4u, 5u}) {  // every chunk with stored bytes (3 is empty)
    SCOPED_TRACE("chunk " + std::to_string(id));
    std::vector<std::byte> b = golden_;
    const uint64_t at = get<uint64_t>(b, entry(id)), stored = get<uint64_t>(b, entry(id) + 8);
    b[at + stored / 2] ^= std::byte{0x10};
    const Reader reader = Reader::fromMemory(b, "flip.iso");  // opening reads no payload
    std::vector<std::byte> out(reader.chunk(id).rawSize);
    expectChecksumMismatch(
        "payload", [&] { reader.payload(id); }, "flip.iso", id, at);
    expectChecksumMismatch(
        "decodePayload", [&] { reader.decodePayload(id, out); }, "flip.iso", id, at);
    expectChecksumMismatch(
        "checkPayload", [&] { reader.checkPayload(id); }, "flip.iso", id, at);
    if (id == 5) {
      expectChecksumMismatch(
          "decodeSurfaceChunk", [&] { decodeSurfaceChunk(reader, id); }, "flip.iso", id, at);
      expectChecksumMismatch(
          "SurfaceModel::load", [&] { SurfaceModel::load(reader); }, "flip.iso", id, at);
    }
    const VerifyResult result = verifyFile(reader);
    ASSERT_EQ(result.problems.size(), 1u);
    EXPECT_EQ(result.problems[0].chunk, id);
    EXPECT_EQ(result.problems[0].offset, at);
    EXPECT_EQ(result.problems[0].reason.rfind("checksum mismatch (table 0x", 0), 0u)
        << result.problems[0].reason;
  }
  // The intact file's surface loads: the refusals above are the flipped byte's.
  EXPECT_NO_THROW(SurfaceModel::load(Reader::fromMemory(golden_, "golden.iso")));
}

TEST(HostileFiles, aFlippedPointsPayloadByteIsRefusedByEveryWayToItsData) {
  test::TempDir dir;
  test::writePointsSeedFile(dir / "points.iso");
  const std::vector<std::byte> good = test::readFile(dir / "points.iso");
  const Reader intact = Reader::fromMemory(good, "points.iso");
  // Points raw and zstd, their values, volume points.
  for (const ChunkInfo& c : intact.chunks()) {
    SCOPED_TRACE(std::string(codecName(c.codec)) + " " + std::string(chunkKindName(c.kind)));
    const bool values = c.kind == kValuesKind;
    const auto decode = [&](const Reader& r) {
      return values ? decodeValuesChunk(r, c.id).size() : decodePointsChunk(r, c.id).size();
    };
    EXPECT_EQ(decode(intact), 60u);
    std::vector<std::byte> b = good;
    b[c.offset + c.storedSize / 2] ^= std::byte{0x01};
    const Reader reader = Reader::fromMemory(b, "flip.iso");
    expectChecksumMismatch(
        "decode", [&] { decode(reader); }, "flip.iso", c.id, c.offset);
    expectChecksumMismatch(
        "payload", [&] { reader.payload(c.id); }, "flip.iso", c.id, c.offset);
    const VerifyResult result = verifyFile(reader);
    ASSERT_EQ(result.problems.size(), 1u);
    EXPECT_NE(result.problems[0].reason.find("checksum mismatch"), std::string::npos);
  }
}

TEST_F(Hostile, metadataThatStartsWithAByteOrderMarkIsRejectedByVerify) {
  std::vector<std::byte> b = golden_;
  const uint64_t metadata = get<uint64_t>(b, trailer_ + 16);
  const std::array<std::byte, 3> mark = {std::byte{0xEF}, std::byte{0xBB}, std::byte{0xBF}};
  b.insert(b.begin() + ptrdiff_t(metadata), mark.begin(), mark.end());
  const size_t trailer = b.size() - 64;
  put<uint64_t>(b, trailer + 24, get<uint64_t>(b, trailer + 24) + 3);
  test::resealChecksums(b);
  const Reader reader = Reader::fromMemory(b, "bom.iso");  // every structure is sound
  EXPECT_EQ(reader.metadata().substr(3), test::goldenMetadata());
  const VerifyResult result = verifyFile(reader);
  ASSERT_EQ(result.problems.size(), 1u);
  EXPECT_FALSE(result.problems[0].chunk.has_value());
  EXPECT_EQ(result.problems[0].offset, metadata);
  EXPECT_NE(result.problems[0].reason.find("byte order mark"), std::string::npos);
}

// A file of surface chunks (level 0, then level-1 children of chunk 0, then more top chunks) with
// these point counts, and a blob with every count; the payloads are not read when opening. The
// writer refuses counts that break the rules, so it writes none and they are put in the table.
std::vector<std::byte> surfaceCountsFile(const std::filesystem::path& path,
                                         const std::vector<uint64_t>& children,
                                         const std::vector<uint64_t>& tops) {
  FileHeader header;
  header.maxLevel = 1;
  header.payloadAlignmentLog2 = 3;
  Writer writer(path, header);
  const std::vector<std::byte> data(8);
  std::vector<uint64_t> counts = {tops.at(0)};
  writer.addChunk({.kind = kSurfaceKind, .codec = Codec::Raw}, data);
  for (size_t i = 0; i < children.size(); ++i) {
    writer.addChunk({.kind = kSurfaceKind, .level = 1, .key = i, .parent = 0, .codec = Codec::Raw},
                    data);
    counts.push_back(children[i]);
  }
  for (size_t i = 1; i < tops.size(); ++i) {
    writer.addChunk({.kind = kSurfaceKind, .codec = Codec::Raw}, data);
    counts.push_back(tops[i]);
  }
  writer.addChunk({.pointCount = ~uint64_t{0}, .codec = Codec::Raw}, data);  // a blob: no rule
  writer.finish();
  std::vector<std::byte> b = test::readFile(path);
  const uint64_t table = get<uint64_t>(b, b.size() - 64);
  for (size_t i = 0; i < counts.size(); ++i)
    put<uint64_t>(b, size_t(table + 80 * i + 40), counts[i]);
  test::resealChecksums(b);
  return b;
}

TEST(HostileFiles, surfacePointCountsAreBoundedByTheirParentsAndBy2To53) {
  test::TempDir dir;
  const uint64_t limit = kMaxPointCount;
  EXPECT_EQ(limit, uint64_t{1} << 53);
  struct Case {
    std::vector<uint64_t> children, tops;
    uint32_t refused;  // the chunk whose count is refused, or kNoParent
  };
  const std::vector<Case> cases = {
      {{6, 4}, {10}, kNoParent},
      {{6, 5}, {10}, 2},
      {{11}, {10}, 1},
      {{~uint64_t{0}}, {10}, 1},
      {{limit, 0}, {limit}, kNoParent},
      {{}, {limit + 1}, 0},
      {{}, {~uint64_t{0}}, 0},
      {{}, {limit - 1, 1}, kNoParent},
      {{}, {limit - 1, 2}, 1},
  };
  for (const Case& c : cases) {
    const std::vector<std::byte> b = surfaceCountsFile(dir / "counts.iso", c.children, c.tops);
    const uint64_t table = get<uint64_t>(b, b.size() - 64);
    // The refused chunk's index in the file: children follow chunk 0, other tops follow them.
    const uint32_t index = c.refused == kNoParent || c.refused <= c.children.size()
                               ? c.refused
                               : uint32_t(c.children.size() + c.refused);
    SCOPED_TRACE(testing::Message() << "tops " << c.tops.size() << ", refused " << index);
    if (c.refused == kNoParent) {
      EXPECT_NO_THROW(Reader::fromMemory(b, "counts.iso"));
      continue;
    }
    try {
      Reader::fromMemory(b, "counts.iso");
      ADD_FAILURE() << "opened";
    } catch (const FileError& error) {
      EXPECT_EQ(error.offset(), table + 80 * index + 40) << error.what();
      EXPECT_NE(error.reason().find("chunk " + std::to_string(index) + ": point count"),
                std::string::npos)
          << error.what();
    }
  }
}

TEST_F(Hostile, framesBeyondTheLimitsAreRejectedAndTheLimitsAccepted) {
  const auto withFrame = [&](std::array<double, 3> origin, double size) {
    return mutate([&](auto& b) {
      for (int a = 0; a < 3; ++a) put<double>(b, 24 + 8 * size_t(a), origin[size_t(a)]);
      put<double>(b, 48, size);
    });
  };
  const double far = std::ldexp(1.0, 31) * 64.0;  // 2^31 golden frame sizes
  const double inf = std::numeric_limits<double>::infinity();
  struct Rejected {
    std::array<double, 3> origin;
    double size;
    uint64_t offset;
  };
  for (const Rejected& r : std::vector<Rejected>{
           {{0, 0, 0}, std::numeric_limits<double>::denorm_min(), 48},
           {{0, 0, 0}, std::ldexp(1.0, -65), 48},
           {{0, 0, 0}, std::ldexp(1.0, 65), 48},
           {{0, 0, 0}, 1e300, 48},
           {{0, 0, 0}, -64.0, 48},
           {{0, 0, 0}, std::nan(""), 48},
           {{0, 0, 0}, inf, 48},
           {{std::nextafter(far, inf), 0, 0}, 64.0, 24},
           {{0, -std::nextafter(far, inf), 0}, 64.0, 32},
           {{0, 0, 1e300}, 64.0, 40},
           {{0, 0, -inf}, 64.0, 40},
           {{1.7e308, 0, 0}, 1e308, 48},
       }) {
    SCOPED_TRACE(testing::Message() << "origin " << r.origin[0] << " " << r.origin[1] << " "
                                    << r.origin[2] << ", size " << r.size);
    const FileError error = openError(withFrame(r.origin, r.size));
    EXPECT_EQ(error.offset(), r.offset) << error.what();
    EXPECT_NE(error.reason().find("header: frame"), std::string::npos) << error.what();
    FileHeader header = test::goldenHeader();
    header.frame = {r.origin, r.size};
    EXPECT_THROW(Writer(test::TempDir() / "frame.iso", header), InternalError);
  }
  const double big = std::ldexp(1.0, 64), small = std::ldexp(1.0, -64);
  for (const Frame& f : std::vector<Frame>{{{0, 0, 0}, small},
                                           {{-small, small, 0}, small},
                                           {{far, -far, far}, 64.0},
                                           {{std::ldexp(big, 31), 0, -std::ldexp(big, 31)}, big}}) {
    const std::vector<std::byte> b = withFrame(f.origin, f.size);
    const Reader reader = Reader::fromMemory(b, "limit.iso");
    EXPECT_EQ(reader.header().frame, f);
  }
}

// One zstd frame (RFC 8878) declaring `declared` content bytes, holding one last Raw block of
// `content` bytes (i % 251): its blocks hold exactly `content` bytes.
std::vector<std::byte> rawBlockFrame(uint32_t content, uint32_t declared) {
  std::vector<std::byte> frame = {std::byte{0x28}, std::byte{0xB5}, std::byte{0x2F},
                                  std::byte{0xFD},
                                  std::byte{0xA0}};  // 4-byte content size, single segment
  for (int i = 0; i < 4; ++i) frame.push_back(std::byte(declared >> (8 * i)));
  const uint32_t block = 1u | content << 3;  // Last_Block, Block_Type 0 (Raw), Block_Size
  for (int i = 0; i < 3; ++i) frame.push_back(std::byte(block >> (8 * i)));
  for (uint32_t i = 0; i < content; ++i) frame.push_back(std::byte(i % 251));
  return frame;
}

// A file whose one chunk (of this kind) stores `frame` as zstd and declares rawSize: written raw,
// then its entry's codec and raw size changed (the stored bytes, and so their checksum, stay).
std::vector<std::byte> zstdChunkFile(const std::vector<std::byte>& frame, uint64_t rawSize,
                                     uint8_t kind) {
  test::TempDir dir;
  {
    Writer writer(dir / "zstd.iso", FileHeader{});
    writer.addChunk(
        {.kind = kind, .pointCount = kind == kPointsKind ? 1u : 0u, .codec = Codec::Raw}, frame);
    writer.finish();
  }
  std::vector<std::byte> b = test::readFile(dir / "zstd.iso");
  const size_t entry = size_t(get<uint64_t>(b, b.size() - 64));
  put<uint64_t>(b, entry + 16, rawSize);
  b[entry + 69] = std::byte{1};  // zstd
  test::resealChecksums(b);
  return b;
}

TEST(HostileFiles, aHugeDeclaredRawSizeIsRefusedBeforeAnythingIsAllocated) {
  // A real frame: declared and held sizes agree, and it decodes.
  const std::vector<std::byte> honest = rawBlockFrame(32768, 32768);
  const std::vector<std::byte> honestFile = zstdChunkFile(honest, 32768, 0);
  const Reader good = Reader::fromMemory(honestFile, "honest.iso");
  const ChunkData data = good.payload(0);
  ASSERT_EQ(data.bytes().size(), 32768u);
  EXPECT_TRUE(std::equal(data.bytes().begin(), data.bytes().end(), honest.end() - 32768));

  // The same blocks declaring 2^30 bytes, frame header and table alike, with a valid checksum:
  // 32780 stored bytes could decode to 2^30 (32768 times as many), so opening accepts the entry.
  const uint32_t huge = uint32_t{1} << 30;
  for (uint8_t kind : {uint8_t{0}, kSurfaceKind, kPointsKind}) {
    SCOPED_TRACE("kind " + std::to_string(kind));
    const std::vector<std::byte> b = zstdChunkFile(rawBlockFrame(32768, huge), huge, kind);
    const Reader reader = Reader::fromMemory(b, "huge.iso");
    struct Read {
      const char* what;
      std::function<void()> read;
      bool refuses;  // whether it reads this chunk's data (and so must refuse it)
    };
    const std::vector<Read> reads = {
        {"payload", [&] { reader.payload(0); }, true},
        {"checkPayload", [&] { reader.checkPayload(0); }, true},
        {"verifyFile", [&] { verifyFile(reader); }, false},
        {"decodeSurfaceChunk", [&] { decodeSurfaceChunk(reader, 0); }, kind == kSurfaceKind},
        {"decodePointsChunk", [&] { decodePointsChunk(reader, 0); }, kind == kPointsKind},
        {"SurfaceModel::load", [&] { SurfaceModel::load(reader); }, kind == kSurfaceKind}};
    for (const Read& r : reads) {
      SCOPED_TRACE(r.what);
      test::largestAllocation = 0;
      try {
        r.read();
        EXPECT_FALSE(r.refuses) << "accepted";
      } catch (const FileError& error) {
        EXPECT_EQ(error.file(), "huge.iso");
        if (r.refuses) {
          EXPECT_NE(error.reason().find("chunk 0: zstd frame's blocks hold at most 32768 bytes"),
                    std::string::npos)
              << error.what();
        }
      }
      EXPECT_LT(test::largestAllocation.load(), size_t{1} << 20);  // not 2^30
    }
    const VerifyResult result = verifyFile(reader);
    ASSERT_EQ(result.problems.size(), 1u);
    EXPECT_NE(result.problems[0].reason.find("blocks hold at most"), std::string::npos);
  }

  // Fewer stored bytes than 2^30 / 32768: the table alone shows it, and opening refuses it.
  const FileError error = openError(zstdChunkFile(rawBlockFrame(1000, huge), huge, kSurfaceKind));
  EXPECT_NE(error.reason().find("chunk 0: raw size is more than 32768 times the stored size"),
            std::string::npos)
      << error.what();
}

}  // namespace
}  // namespace iso
