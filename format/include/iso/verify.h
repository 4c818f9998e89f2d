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

// Check every chunk's data through the Reader's checked accessors (its checksum, that a zstd
// payload decodes to exactly rawSize bytes), that every surface and points chunk follows its
// rules, that all padding is zero and that the metadata does not start with a byte order mark.
// (Whether the metadata is a JSON object is for the caller to check: this library parses no
// JSON.)
VerifyResult verifyFile(const Reader& reader);

// "chunk 3 (level 1, key 0x5) at byte 8192: REASON" or "byte 300: REASON".
std::string describe(const Reader& reader, const VerifyProblem& problem);

}  // namespace iso
