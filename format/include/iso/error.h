// What can go wrong, and what each becomes at the command line (tools/iso/main.cpp, runGuarded):
//
//   UsageError     an impossible option or parameter, found before any work: its message, exit 2.
//                  The only error that exits with 2.
//   FileError      a problem with a file (unreadable, malformed, truncated or hostile input, a
//                  failed write): the file's name, the byte offset when there is one, the reason;
//                  exit 1.
//   InternalError  a failed ISO_CHECK (iso/check.h): a bug in iso, never a property of the input;
//                  exit 1 with the expression and the source line.
//   other          std::bad_alloc ("out of memory"), errors of the libraries underneath (Vulkan,
//                  OpenVDB) and of a stage (ConvertError: the points define no surface): exit 1.
//
// Nothing the user had is replaced or left half written in any of these cases (iso/writer.h,
// iso/atomic_file.h). The format library's checks of what its callers pass (a header or a chunk
// that breaks the format's rules, a buffer too small, a writer used after it finished) throw
// InternalError too: a bug of the caller. What comes from a file is checked by the readers, and
// what breaks a rule there is a FileError (tryLayoutSurface reports a topology's problem without
// throwing for that reason).
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

namespace iso {

// A problem with a file, with the file's name, the byte offset it concerns (when there is one) and
// the reason. what() reads "NAME: byte OFFSET: REASON" (or "NAME: REASON").
class FileError : public std::runtime_error {
 public:
  FileError(std::string file, std::optional<uint64_t> offset, std::string reason);

  const std::string& file() const { return file_; }
  std::optional<uint64_t> offset() const { return offset_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string file_;
  std::optional<uint64_t> offset_;
  std::string reason_;
};

// An impossible option or parameter: the message names the option as the user wrote it.
class UsageError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

}  // namespace iso
