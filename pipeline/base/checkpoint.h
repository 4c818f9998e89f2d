// Checkpoints of a resumable run (`iso convert --resume`, specs/pipeline.md §15): the results of
// the stages done, in files that a kill leaves behind, so that a run started again with the same
// inputs and options goes on from the last stage it finished.
//
// A checkpoint is one file of named sections (a JSON value or an array of plain values), in a
// fixed order that its reader asks for again. It is written under a temporary name, flushed to
// the disk and renamed into place, so a file with the checkpoint's name is always whole; its
// header holds the run's fingerprint and every section its length and checksum (XXH3-64), checked
// as it is read. A checkpoint of another run, a damaged or a cut one is never used.
//
// Checkpoints are large (a chunk's points and tree, hundreds of MB) and written once, read at most
// once: they go around the page cache (O_DIRECT, in aligned blocks) where the file system allows,
// so that they neither evict the pages a memory budget keeps nor pay for caching them (specs/
// pipeline.md §15, "Resume": on the 2-core test machine a buffered GB costs 3 s of system time
// to write and 1.8 s to read, an unbuffered one 0.1 s).
//
// Threading: an object is used by one thread at a time.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "iso/temporary_files.h"

namespace iso {

// A checkpoint that cannot be used: cut, damaged, or of another run.
class CheckpointError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A buffer of whole aligned blocks for unbuffered file I/O, and whether the file takes it.
class AlignedBlocks {
 public:
  static constexpr size_t kAlignment = 4096;
  static constexpr size_t kCapacity = size_t{8} << 20;
  AlignedBlocks();
  std::byte* data() const { return data_.get(); }
  size_t size = 0;      // bytes in use
  bool direct = false;  // the file descriptor has O_DIRECT
  // Clear O_DIRECT on fd (a tail that is not a whole block, or a file system that refuses it).
  void stopDirect(int fd);

 private:
  struct Free {
    void operator()(std::byte* p) const;
  };
  std::unique_ptr<std::byte[], Free> data_;
};

class CheckpointWriter {
 public:
  // Writes `final` under a temporary name beside it; FileError naming it when it cannot.
  CheckpointWriter(std::filesystem::path final, const std::string& fingerprint);
  ~CheckpointWriter();  // without commit(): the temporary file is removed
  CheckpointWriter(const CheckpointWriter&) = delete;
  CheckpointWriter& operator=(const CheckpointWriter&) = delete;

  void json(const std::string& name, const nlohmann::json& value);
  template <typename Vector>
  void array(const std::string& name, const Vector& values) {
    using T = typename Vector::value_type;
    static_assert(std::is_trivially_copyable_v<T>);
    bytes(name, {reinterpret_cast<const std::byte*>(values.data()), values.size() * sizeof(T)});
  }
  // Flush, fsync and rename into place; returns the file's size.
  uint64_t commit();

 private:
  void bytes(const std::string& name, std::span<const std::byte> data);
  void put(std::span<const std::byte> data);
  void flush();  // the buffer to the file (a whole number of blocks unless committing)
  std::filesystem::path final_, staged_;
  TemporaryRegistration registration_;
  int fd_ = -1;
  uint64_t written_ = 0;
  AlignedBlocks buffer_;
};

class CheckpointReader {
 public:
  // CheckpointError when the file is not a checkpoint of the run with this fingerprint.
  CheckpointReader(const std::filesystem::path& path, const std::string& fingerprint);
  ~CheckpointReader();
  CheckpointReader(const CheckpointReader&) = delete;
  CheckpointReader& operator=(const CheckpointReader&) = delete;

  // The next section, which must be `name`; CheckpointError when it is not, or is damaged.
  nlohmann::json json(const std::string& name);
  template <typename Vector>
  void array(const std::string& name, Vector& values) {
    values.clear();
    appendArray(name, values);
  }
  // The section `name`, as array(), after the values already in `values`.
  template <typename Vector>
  void appendArray(const std::string& name, Vector& values) {
    using T = typename Vector::value_type;
    static_assert(std::is_trivially_copyable_v<T>);
    const uint64_t size = begin(name);
    if (size % sizeof(T) != 0) fail("section " + name + " is not a whole number of values");
    const size_t before = values.size();
    values.resize(before + size / sizeof(T));
    const std::span<std::byte> data(reinterpret_cast<std::byte*>(values.data() + before), size);
    read(data);
    check(name, data);
  }
  // Every section was read and the file ends there; CheckpointError when not.
  void finish();
  uint64_t size() const { return size_; }

 private:
  uint64_t begin(const std::string& name);
  void read(std::span<std::byte> data);
  void check(const std::string& name, std::span<const std::byte> data);  // the stored checksum
  [[noreturn]] void fail(const std::string& why) const;
  std::filesystem::path path_;
  int fd_ = -1;
  uint64_t size_ = 0, offset_ = 0;
  AlignedBlocks buffer_;      // the file's bytes from bufferStart_
  uint64_t bufferStart_ = 0;  // a multiple of the block size
};

// The directory of a resumable run's checkpoints. It is made when missing, and removed with its
// checkpoints by finish() when the run succeeds; a run that is interrupted or fails keeps it.
class ResumeState {
 public:
  // `fingerprint`: what the run's results depend on (inputs, options, version), as text. A state
  // of another fingerprint found there is removed (with a note).
  ResumeState(std::filesystem::path directory, std::string fingerprint);
  const std::filesystem::path& directory() const { return directory_; }
  const std::string& fingerprint() const { return fingerprint_; }
  std::filesystem::path path(const std::string& name) const { return directory_ / name; }
  // Whether a file of that name is there (it may still be unusable: open() says).
  bool has(const std::string& name) const;
  // The checkpoint `name` of this run, or null when there is none or it cannot be used (it is
  // removed then, and a note says why).
  std::unique_ptr<CheckpointReader> open(const std::string& name);
  std::unique_ptr<CheckpointWriter> create(const std::string& name) const;
  // A checkpoint that turned out damaged while it was read: removed, with a note.
  void discard(const std::string& name, const std::string& why);
  // Remove the checkpoints whose names start so.
  void removeStartingWith(const std::string& prefix);
  // Remove every checkpoint and the directory.
  void finish();
  // What the run should be told about the state it found (checkpoints it could not use).
  const std::vector<std::string>& notes() const { return notes_; }

 private:
  std::filesystem::path directory_;
  std::string fingerprint_;
  std::vector<std::string> notes_;
};

}  // namespace iso
