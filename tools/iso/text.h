// Number and text formatting for people.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include "iso/error.h"

namespace iso::cli {

std::string withSeparators(uint64_t value);                     // 1234567 -> "1,234,567"
std::string humanBytes(uint64_t bytes);                         // 1536 -> "1.5 KiB"
// Bytes from "2G", "512M", "1.5G", "100000" (binary units); UsageError naming the
// option otherwise.
uint64_t parseSize(const std::string& text, const char* option);
std::string indentLines(const std::string& text, int columns);  // indent every line but the first

// Write text to a file atomically (a temporary file renamed into place); throws iso::FileError.
void writeTextFile(const std::filesystem::path& path, const std::string& text);

}  // namespace iso::cli
