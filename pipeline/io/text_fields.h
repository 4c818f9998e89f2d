// Field splitting for text formats (PLY ASCII, XYZ-like files), without iostreams or locales;
// numbers parsed by base/text.h (std::from_chars).
#pragma once

#include <charconv>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <system_error>

#include "base/text.h"

namespace iso::io {

inline bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }
inline bool isBlankCommaOrSemicolon(char c) { return isBlank(c) || c == ',' || c == ';'; }

// Take the next field of `rest`, a run of characters that are not separators; false when only
// separators are left. A run of separators counts as one.
template <bool (*isSeparator)(char)>
bool nextField(std::string_view& rest, std::string_view& field) {
  size_t begin = 0;
  while (begin < rest.size() && isSeparator(rest[begin])) ++begin;
  if (begin == rest.size()) {
    rest = {};
    return false;
  }
  size_t end = begin + 1;
  while (end < rest.size() && !isSeparator(rest[end])) ++end;
  field = rest.substr(begin, end - begin);
  rest.remove_prefix(end);
  return true;
}

// Numbers are parsed by base/text.h, for every part of the project.
using iso::parseInteger;
using iso::parseNumber;

}  // namespace iso::io
