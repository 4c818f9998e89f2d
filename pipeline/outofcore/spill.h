// Points on disk for the out-of-core conversion (specs/pipeline.md, "Out of core"):
//
//   RawSpill      the input points as read, in input order (world coordinates in double), so that
//                 each input file is parsed once whatever the number of passes
//   Distribution  the same points counting-sorted by Morton cell into chunks: octree cells (Morton
//                 prefixes) of at most a budget of points, each contiguous on disk and sorted by
//                 fine cell within, so that a chunk and the halo around it load with a few reads
//
// Files live in a temporary directory named like every iso temporary (".NAME.PID-N.isotmp"), which
// is removed when the object that made it is destroyed, on Ctrl-C, and by the next run after a
// kill -9 (iso/temporary_files.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <glm/vec3.hpp>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "iso/format.h"
#include "iso/temporary_files.h"
#include "pipeline/io/point_cloud.h"

namespace iso {

// A directory for temporary files, removed with everything in it when destroyed.
class SpillDirectory {
 public:
  // Creates ".iso-spill.PID-N.isotmp" under parent (which must exist); with a tag,
  // ".iso-spill-TAG.PID-N.isotmp" (the ranks of a distributed run, whose PIDs may be the same on
  // different machines).
  explicit SpillDirectory(const std::filesystem::path& parent, const std::string& tag = "");
  ~SpillDirectory();
  SpillDirectory(const SpillDirectory&) = delete;
  SpillDirectory& operator=(const SpillDirectory&) = delete;
  const std::filesystem::path& path() const { return path_; }
  // A new file name in the directory, registered for removal on interruption.
  std::filesystem::path newFile(const std::string& name);
  // Bytes of all files in the directory now.
  uint64_t bytes() const;

 private:
  std::filesystem::path path_;
  std::vector<TemporaryRegistration> registrations_;
};

// A file of fixed-size records, written by appending and read by record ranges. Errors throw
// iso::FileError naming the file (a full disk among them).
class RecordFile {
 public:
  RecordFile(std::filesystem::path path, size_t recordBytes);
  ~RecordFile();
  RecordFile(const RecordFile&) = delete;
  RecordFile& operator=(const RecordFile&) = delete;

  size_t recordBytes() const { return recordBytes_; }
  uint64_t size() const { return count_; }  // records
  void append(std::span<const std::byte> records);
  // Write records at a record index (within or at the end of the file), bypassing the buffer.
  void writeAt(uint64_t index, std::span<const std::byte> records);
  void flush();
  // Read records [first, first + count) into out (resized).
  void read(uint64_t first, uint64_t count, std::vector<std::byte>& out) const;
  const std::filesystem::path& path() const { return path_; }

 private:
  [[noreturn]] void fail(const std::string& what, int error) const;
  std::filesystem::path path_;
  size_t recordBytes_;
  uint64_t charged_ = 0;  // bytes charged to the temporary disk (the file's size)
  int fd_ = -1;
  uint64_t count_ = 0;
  std::vector<std::byte> buffer_;
};

// What a point record holds beyond its position.
struct PointLayout {
  bool normals = false;
  bool colors = false;
  std::string scalar;  // the one extra carried (a double), by name; empty: none
};

// The input points in input order: position (3 double), normal (3 float), color (3 float),
// scalar (double).
class RawSpill {
 public:
  RawSpill(SpillDirectory& directory, PointLayout layout);
  const PointLayout& layout() const { return layout_; }
  void append(const PointCloud& batch);
  void finish();
  uint64_t size() const { return file_->size(); }
  // Bounds of all positions appended.
  glm::dvec3 lo() const { return lo_; }
  glm::dvec3 hi() const { return hi_; }
  // Call f with batches of points in input order and the input index of each batch's first point.
  void forEachBatch(const std::function<void(const PointCloud&, uint64_t first)>& f) const;

 private:
  PointLayout layout_;
  std::unique_ptr<RecordFile> file_;
  glm::dvec3 lo_, hi_;
};

// One chunk: a Morton cell and its points' record range in the distribution.
struct SpillChunk {
  uint8_t level = 0;
  uint64_t key = 0;  // the cell's Morton code at `level`
  uint64_t begin = 0, end = 0;
  uint64_t size() const { return end - begin; }
};

// Points of a chunk (and of the halo around it) as loaded from a distribution.
struct LoadedPoints {
  PointCloud cloud;              // world positions and attributes
  std::vector<uint32_t> source;  // input index of each point
};

// The raw spill counting-sorted into chunks of at most maxChunkPoints points (a cell at the
// histogram's finest level holding more becomes one larger chunk). `keep` (when given) says which
// input points take part. Chunks follow Morton order; within a chunk the points are ordered by
// fine cell, then by input index.
class Distribution {
 public:
  static constexpr int kFineLevel = 7;  // histogram cells: 128³

  Distribution(SpillDirectory& directory, const RawSpill& raw, const Frame& frame,
               uint64_t maxChunkPoints, const std::vector<uint8_t>* keep = nullptr);
  const std::vector<SpillChunk>& chunks() const { return chunks_; }
  uint64_t size() const { return file_->size(); }
  // The points of a chunk.
  LoadedPoints load(const SpillChunk& chunk) const;
  // The points of other chunks whose frame position lies in the box [lo, hi] (frame units),
  // read cell by cell.
  LoadedPoints loadBox(const glm::dvec3& lo, const glm::dvec3& hi, const SpillChunk& except) const;

 private:
  struct FineCell {
    uint64_t key;  // at kFineLevel
    uint64_t begin, end;
  };
  void decode(const std::vector<std::byte>& records, LoadedPoints& out,
              const std::function<bool(const glm::dvec3&)>& accept) const;

  PointLayout layout_;
  Frame frame_;
  std::unique_ptr<RecordFile> file_;
  std::vector<SpillChunk> chunks_;
  std::vector<FineCell> cells_;  // occupied fine cells, in Morton order
};

}  // namespace iso
