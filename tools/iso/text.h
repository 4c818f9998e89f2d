// Number and text formatting for people.
#pragma once

#include <cstdint>
#include <string>

namespace iso::cli {

std::string withSeparators(uint64_t value);                     // 1234567 -> "1,234,567"
std::string humanBytes(uint64_t bytes);                         // 1536 -> "1.5 KiB"
std::string indentLines(const std::string& text, int columns);  // indent every line but the first

}  // namespace iso::cli
