// The files a run makes besides its temporary data: its outputs, checked before any work starts
// and written all or none, and directories made for its temporary files (`iso convert --tmp`).
// Every error throws iso::FileError naming the path and what is wrong with it.
//
// Threading: an object is used by one thread at a time.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "iso/temporary_files.h"

namespace iso {

// Refuse a path that cannot become an output: its directory does not exist, is not a directory
// or cannot be written in; the path is a directory; or it exists and `replace` is false. `role`
// names where the path came from ("-o", "--mesh") in the message. An empty path is a UsageError.
void checkOutputPath(const std::filesystem::path& path, const std::string& role, bool replace);

// Refuse an output that is the same file as an input (through a link, too).
void refuseOutputOverInput(const std::filesystem::path& output, const std::filesystem::path& input,
                           const std::string& role);

// Whether two paths name one file: the same file when both exist (through links too), else the
// same absolute path once "." and ".." and the links of the existing part are resolved.
bool namesSameFile(const std::filesystem::path& a, const std::filesystem::path& b);

// Write bytes to path, replacing it only once all are written (iso::AtomicFile): a full disk is a
// FileError naming path, and leaves what path held.
void writeFileBytes(const std::filesystem::path& path, const std::vector<uint8_t>& bytes);
// A whole file's bytes; a FileError naming path when it cannot be opened or read.
std::vector<uint8_t> readFileBytes(const std::filesystem::path& path);

// Claim a piece of work shared through a directory that several processes see: makes `path` with
// O_EXCL and says whether this call made it (exactly one caller does); a FileError when it can
// neither make it nor find it there.
bool claimFile(const std::filesystem::path& path);

// Outputs written together, all or none. Each is written under a temporary name beside its final
// path (stage()); commit() renames them all into place once every one is complete. If a rename
// fails, the renames done are undone, so that every final path holds what it held before, and
// nothing new is left. Destroyed without commit(), the group removes the staged files.
class OutputGroup {
 public:
  OutputGroup() = default;
  ~OutputGroup();
  OutputGroup(const OutputGroup&) = delete;
  OutputGroup& operator=(const OutputGroup&) = delete;

  // The path to write `final` at: ".NAME.PID-N.isotmp" in its directory, removed on an interrupt
  // (iso/temporary_files.h) and by a later run if this one is killed. The name does not keep the
  // final extension: a writer must not pick its format by the extension.
  std::filesystem::path stage(const std::filesystem::path& final);
  // Rename every staged file over its final path (see above). The caller defers interrupts around
  // it when it must not be cut in the middle.
  void commit();

 private:
  struct Output {
    std::filesystem::path final, staged, backup;  // backup: the old file, while committing
    TemporaryRegistration registration;           // of staged
  };
  void undo(size_t done) noexcept;

  std::vector<Output> outputs_;
  bool committed_ = false;
};

// An output that is a directory of files (a tileset): written into a temporary directory beside
// `final` (".NAME.new.PID-N.isotmp", which a later run removes if this one is killed), then
// renamed into place by commit(), replacing an old directory only then. Destroyed without
// commit(), the temporary directory and what it holds are removed.
class OutputDirectory {
 public:
  // FileError when final's directory cannot take it, or final exists and `replace` is false, or
  // exists and is not a directory. `role` names the option in messages.
  OutputDirectory(const std::filesystem::path& final, const std::string& role, bool replace);
  ~OutputDirectory();
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;

  const std::filesystem::path& path() const { return staged_; }  // where to write
  void commit();

 private:
  std::filesystem::path final_, staged_;
  TemporaryRegistration registration_;
  bool committed_ = false;
};

// A directory and whichever of its parents did not exist, made; those made are removed again
// (deepest first, each only if empty) when the object is destroyed or the process is interrupted.
class MadeDirectories {
 public:
  // Makes `path`; FileError naming the directory that could not be made, or a part of `path`
  // that exists and is not a directory. `role` names the option in the message.
  MadeDirectories(const std::filesystem::path& path, const std::string& role);
  ~MadeDirectories();
  MadeDirectories(const MadeDirectories&) = delete;
  MadeDirectories& operator=(const MadeDirectories&) = delete;

  // The directories made, outermost first (none when `path` existed).
  const std::vector<std::filesystem::path>& made() const { return made_; }

 private:
  void removeMade() noexcept;

  std::vector<std::filesystem::path> made_;
  std::vector<TemporaryRegistration> registrations_;
};

}  // namespace iso
