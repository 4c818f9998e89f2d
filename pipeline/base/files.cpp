#include "pipeline/base/files.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <optional>
#include <span>

#include "iso/atomic_file.h"
#include "iso/error.h"

namespace iso {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const fs::path& path, const std::string& reason) {
  throw FileError(path.string(), std::nullopt, reason);
}

fs::path directoryOf(const fs::path& path) {
  return path.has_parent_path() ? path.parent_path() : fs::path(".");
}

// `path` without the separators it ends with: "tiles/" and "tiles//" name the directory "tiles",
// whose parent is where it is made and whose name its temporary sibling takes.
fs::path withoutTrailingSeparators(fs::path path) {
  while (!path.has_filename() && path.has_relative_path()) path = path.parent_path();
  return path;
}

// Why `directory` cannot hold a file: it or a parent is missing, or a parent is not a directory.
std::string missingDirectory(const fs::path& directory) {
  std::error_code error;
  for (fs::path p = directory; p.has_relative_path(); p = p.parent_path()) {
    const fs::file_status status = fs::status(p, error);
    if (status.type() == fs::file_type::not_found) continue;
    if (!fs::is_directory(status)) return p.string() + " is not a directory";
    break;
  }
  return "the directory " + directory.string() + " does not exist";
}

// ".NAME.WHAT.PID-N.isotmp" beside `path`: an iso temporary name (iso/temporary_files.h).
fs::path siblingName(const fs::path& path, const char* what) {
  static std::atomic<uint64_t> sequence{0};
  return directoryOf(path) /
         ("." + path.filename().string() + "." + what + "." + std::to_string(::getpid()) + "-" +
          std::to_string(sequence++) + ".isotmp");
}

// Make a rename durable; a failure leaves complete files, so it is not an error.
void syncDirectory(const fs::path& directory) {
  const int fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

}  // namespace

void checkOutputPath(const fs::path& path, const std::string& role, bool replace) {
  if (path.empty()) throw UsageError(role + " names no file (an empty name)");
  const fs::path directory = directoryOf(path);
  std::error_code error;
  const fs::file_status where = fs::status(directory, error);
  if (where.type() == fs::file_type::not_found) fail(path, missingDirectory(directory));
  if (error)
    fail(path, "cannot reach the directory " + directory.string() + ": " + error.message());
  if (!fs::is_directory(where)) fail(path, directory.string() + " is not a directory");
  if (::access(directory.c_str(), W_OK | X_OK) != 0)
    fail(path, "cannot write in the directory " + directory.string() + ": " + std::strerror(errno));
  const fs::file_status status = fs::status(path, error);
  if (fs::is_directory(status) || !path.has_filename())
    fail(path, "is a directory (" + role + " wants a file name)");
  if (fs::exists(status) && !replace) fail(path, "exists already (use --force to replace it)");
}

void refuseOutputOverInput(const fs::path& output, const fs::path& input, const std::string& role) {
  std::error_code error;
  if (fs::equivalent(output, input, error))
    fail(output, "is also an input (" + role + " would replace " + input.string() + ")");
}

bool namesSameFile(const fs::path& a, const fs::path& b) {
  std::error_code error;
  if (fs::exists(a, error) && fs::exists(b, error)) return fs::equivalent(a, b, error);
  const fs::path canonicalA = fs::weakly_canonical(a, error);
  if (error) return false;
  return canonicalA == fs::weakly_canonical(b, error) && !error;
}

void writeFileBytes(const fs::path& path, const std::vector<uint8_t>& bytes) {
  AtomicFile file(path);
  file.write(std::as_bytes(std::span(bytes)));
  file.commit();
}

std::vector<uint8_t> readFileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path.string(), std::nullopt, "cannot be opened");
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
  if (in.bad()) throw FileError(path.string(), std::nullopt, "cannot be read");
  return bytes;
}

// ---- OutputDirectory

OutputDirectory::OutputDirectory(const fs::path& final, const std::string& role, bool replace)
    : final_(withoutTrailingSeparators(final)) {
  std::error_code error;
  const fs::file_status status = fs::symlink_status(final_, error);
  if (fs::exists(status)) {
    if (!fs::is_directory(status)) fail(final_, "exists and is not a directory (" + role + ")");
    if (!replace) fail(final_, "exists (use --force to replace it)");
  }
  const fs::path parent = directoryOf(final_);
  if (!fs::is_directory(parent, error)) fail(final_, missingDirectory(parent));
  staged_ = siblingName(final_, "new");
  if (::mkdir(staged_.c_str(), 0755) != 0)
    fail(final_, "cannot be made (" + role + "): " + std::strerror(errno));
  registration_ = TemporaryRegistration(staged_);
}

OutputDirectory::~OutputDirectory() {
  if (committed_) return;
  std::error_code ignored;
  fs::remove_all(staged_, ignored);
}

void OutputDirectory::commit() {
  std::error_code error;
  fs::path backup;
  if (fs::exists(fs::symlink_status(final_, error))) {
    backup = siblingName(final_, "old");
    if (::rename(final_.c_str(), backup.c_str()) != 0)
      fail(final_, std::string("cannot be moved aside to replace it: ") + std::strerror(errno));
  }
  if (::rename(staged_.c_str(), final_.c_str()) != 0) {
    const int reason = errno;
    if (!backup.empty()) ::rename(backup.c_str(), final_.c_str());
    fail(final_, "cannot rename " + staged_.string() + " to it: " + std::strerror(reason) +
                     "; no output was written");
  }
  committed_ = true;
  registration_ = TemporaryRegistration();
  if (!backup.empty()) fs::remove_all(backup, error);
  syncDirectory(directoryOf(final_));
}

// ---- OutputGroup

OutputGroup::~OutputGroup() {
  if (committed_) return;
  for (const Output& o : outputs_) ::unlink(o.staged.c_str());
}

fs::path OutputGroup::stage(const fs::path& final) {
  Output& o = outputs_.emplace_back();
  o.final = final;
  o.staged = siblingName(final, "new");
  o.registration = TemporaryRegistration(o.staged);
  return o.staged;
}

void OutputGroup::commit() {
  for (size_t i = 0; i < outputs_.size(); ++i) {
    Output& o = outputs_[i];
    struct stat old {};
    int error = 0;
    if (::lstat(o.final.c_str(), &old) == 0 && S_ISDIR(old.st_mode)) {
      error = EISDIR;
    } else if (::lstat(o.final.c_str(), &old) == 0) {
      // The old file stays reachable until all are in place: a second link to it (or, where
      // the file system has no links, the file itself moved aside).
      o.backup = siblingName(o.final, "old");
      if (::link(o.final.c_str(), o.backup.c_str()) != 0 &&
          ::rename(o.final.c_str(), o.backup.c_str()) != 0) {
        error = errno;
        o.backup.clear();
      }
    }
    if (error == 0 && ::rename(o.staged.c_str(), o.final.c_str()) != 0) error = errno;
    if (error != 0) {
      undo(i + 1);
      fail(o.final, "cannot rename " + o.staged.string() + " to it: " + std::strerror(error) +
                        "; no output was written");
    }
  }
  committed_ = true;
  for (Output& o : outputs_) {
    if (!o.backup.empty()) ::unlink(o.backup.c_str());
    o.registration = TemporaryRegistration();
    syncDirectory(directoryOf(o.final));
  }
}

void OutputGroup::undo(size_t done) noexcept {
  for (size_t i = done; i-- > 0;) {
    Output& o = outputs_[i];
    std::error_code error;
    const bool renamed = !fs::exists(o.staged, error);
    if (!o.backup.empty()) {
      ::rename(o.backup.c_str(), o.final.c_str());  // the old file back, over the new one
      ::unlink(o.backup.c_str());  // left when both names were links to the same file
    } else if (renamed) {
      ::unlink(o.final.c_str());
    }
    o.backup.clear();
  }
}

// ---- MadeDirectories

MadeDirectories::MadeDirectories(const fs::path& path, const std::string& role) {
  fs::path target = path.lexically_normal();
  if (!target.has_filename() && target.has_parent_path()) target = target.parent_path();
  std::vector<fs::path> missing;  // deepest first
  std::error_code error;
  for (fs::path p = target; !p.empty(); p = p.parent_path()) {
    const fs::file_status status = fs::status(p, error);
    if (status.type() != fs::file_type::not_found) {
      if (!fs::is_directory(status)) fail(p, "is not a directory (" + role + ")");
      break;
    }
    missing.push_back(p);
    if (!p.has_relative_path() || p == p.parent_path()) break;
  }
  for (auto p = missing.rbegin(); p != missing.rend(); ++p) {
    TemporaryRegistration registration(*p);  // before it exists, as temporary files are
    if (::mkdir(p->c_str(), 0777) != 0) {
      const int code = errno;
      if (code == EEXIST && fs::is_directory(*p, error)) continue;  // made meanwhile: not ours
      removeMade();
      fail(*p, "cannot make this directory for " + role + " " + path.string() + ": " +
                   std::strerror(code));
    }
    made_.push_back(*p);
    registrations_.push_back(std::move(registration));
  }
}

MadeDirectories::~MadeDirectories() { removeMade(); }

void MadeDirectories::removeMade() noexcept {
  for (auto p = made_.rbegin(); p != made_.rend(); ++p) ::rmdir(p->c_str());
  made_.clear();
  registrations_.clear();
}

bool claimFile(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_CREAT | O_EXCL | O_WRONLY | O_CLOEXEC, 0644);
  if (fd >= 0) {
    ::close(fd);
    return true;
  }
  if (errno == EEXIST) return false;
  throw FileError(path.string(), std::nullopt,
                  std::string("cannot claim: ") + std::strerror(errno));
}

}  // namespace iso
