// Helpers shared by the format tests and fuzzers.
#pragma once

#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "iso/surface.h"
#include "iso/writer.h"

namespace iso::test {

// A fresh directory under the system temporary directory, removed with everything in it.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// A directory that no file can be made in, not even by root: a tmpfs mounted on it and made
// read-only by lock() (as root), or mode 0555 (other users). What is written there before lock()
// stays readable. ok() is false where neither works (a test then skips).
class ReadOnlyDirectory {
 public:
  explicit ReadOnlyDirectory(const std::filesystem::path& path);
  ~ReadOnlyDirectory();
  ReadOnlyDirectory(const ReadOnlyDirectory&) = delete;
  ReadOnlyDirectory& operator=(const ReadOnlyDirectory&) = delete;
  bool ok() const { return ok_; }
  void lock();

 private:
  std::filesystem::path path_;
  bool mounted_ = false, ok_ = false;
};

// The file or folder a test program was built to find at `built` (a path in the checkout it was
// built from), or the one the environment variable `variable` names instead: for test programs
// run from a copy elsewhere (the bundle of `tools/run device-bundle`).
std::filesystem::path builtPath(const char* variable, const char* built);

std::vector<std::byte> readFile(const std::filesystem::path& path);
void writeFile(const std::filesystem::path& path, const std::vector<std::byte>& bytes);

// Recompute the header, chunk table, metadata and trailer checksums of a possibly modified file in
// place, wherever the trailer's fields point inside the file, so that tests and fuzzers reach the
// structural checks behind the checksums. Files too small to hold a header and trailer are left.
void resealChecksums(std::vector<std::byte>& bytes);

// A valid file's bytes with chunk `chunk`'s table entry changed by `change` (each field put where
// specs/iso-format.md, "Chunk table", puts it) and every checksum recomputed: how tests make a
// file whose table breaks a rule, which the writer refuses to write.
std::vector<std::byte> withChangedEntry(std::vector<std::byte> bytes, uint32_t chunk,
                                        const std::function<void(ChunkInfo&)>& change);

// The content of tests/data/golden-v2.iso: header, chunks and data, and metadata.
struct GoldenChunk {
  ChunkDesc desc;
  std::vector<std::byte> data;
};
FileHeader goldenHeader();
std::vector<GoldenChunk> goldenChunks();
std::string goldenMetadata();
// The golden file's surface chunk (chunk 5) before quantization.
struct GoldenSurface {
  SurfaceTopology topology;
  CornerValues leafValues, lodValues;
};
GoldenSurface goldenSurface();
// Write the golden file's content with the current writer.
void writeGoldenFile(const std::filesystem::path& path);
// A small file of two points chunks (with and without colors and normals), payloads 8-aligned.
void writePointsSeedFile(const std::filesystem::path& path);
// The golden file with a lighting chunk for each surface chunk (a seed for the fuzzer).
void writeLightingSeedFile(const std::filesystem::path& golden, const std::filesystem::path& path);

}  // namespace iso::test
