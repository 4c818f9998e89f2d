// Full verification of an opened .iso file: everything Reader::open does not touch.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "iso/reader.h"

namespace iso {

struct VerifyProblem {
  std::optional<uint32_t> chunk;  // the chunk concerned, if any
  uint64_t offset = 0;            // byte offset in the file
  std::string reason;
};

struct VerifyResult {
  std::vector<VerifyProblem> problems;
  uint64_t chunksChecked = 0;
  uint64_t bytesChecked = 0;  // file bytes covered by a check
  bool ok() const { return problems.empty(); }
};

// Check every payload's checksum, that every zstd payload decodes to exactly rawSize bytes, that
// every surface chunk follows its rules, and that all padding is zero. (Whether the metadata is a
// JSON object is for the caller to check.)
VerifyResult verifyFile(const Reader& reader);

// "chunk 3 (level 1, key 0x5) at byte 8192: REASON" or "byte 300: REASON".
std::string describe(const Reader& reader, const VerifyProblem& problem);

}  // namespace iso
