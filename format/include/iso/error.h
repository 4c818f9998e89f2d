// Errors about files: unreadable, malformed, truncated or hostile input, and failed writes.
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

}  // namespace iso
