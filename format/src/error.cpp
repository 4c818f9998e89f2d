#include "iso/error.h"

#include "iso/check.h"

namespace iso {
namespace {

std::string formatMessage(const std::string& file, std::optional<uint64_t> offset,
                          const std::string& reason) {
  std::string message = file + ": ";
  if (offset) message += "byte " + std::to_string(*offset) + ": ";
  return message + reason;
}

}  // namespace

FileError::FileError(std::string file, std::optional<uint64_t> offset, std::string reason)
    : std::runtime_error(formatMessage(file, offset, reason)),
      file_(std::move(file)),
      offset_(offset),
      reason_(std::move(reason)) {}

void failCheck(const char* expression, const char* file, int line) {
  throw InternalError(std::string("internal error: check failed: ") + expression + " (" + file +
                      ":" + std::to_string(line) + ")");
}

}  // namespace iso
