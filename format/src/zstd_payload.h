// zstd payloads (specs/iso-format.md, "Payloads"): the checks made before any memory is allocated
// for the data, decoding into a buffer, and decoding through a small buffer to check a frame.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace iso::detail {

// Why the stored bytes are not exactly one zstd frame whose content size is rawSize and whose
// blocks can hold that many bytes, or empty when they are. Reads the frame and block headers
// alone: nothing is decoded or allocated.
std::string zstdFrameProblem(std::span<const std::byte> stored, uint64_t rawSize);

// Decode a frame that zstdFrameProblem accepted into out, exactly out.size() bytes; the reason it
// does not decode to that, or empty.
std::string zstdDecodeProblem(std::span<const std::byte> stored, std::span<std::byte> out);

// The same check as zstdDecodeProblem through a small buffer, so that checking needs little memory
// however large the data.
std::string zstdStreamProblem(std::span<const std::byte> stored, uint64_t rawSize);

}  // namespace iso::detail
