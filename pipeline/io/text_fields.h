// Field splitting and number parsing for text formats (PLY ASCII, XYZ-like files), without
// iostreams or locales: std::from_chars.
#pragma once

#include <charconv>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <system_error>

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

// Parse all of `text` as a decimal or scientific number ("inf" and "nan" included) of type T
// (float or double), rounded once to the nearest value. Values beyond the range become infinities
// (and tiny ones zero or subnormals), as strtod makes them.
template <typename T = double>
bool parseNumber(std::string_view text, T& value) {
  if (text.starts_with('+') && !text.starts_with("+-")) text.remove_prefix(1);
  const char* last = text.data() + text.size();
  const auto [end, error] = std::from_chars(text.data(), last, value);
  if (end != last || text.empty()) return false;
  if (error == std::errc::result_out_of_range) {
    const std::string copy(text);
    if constexpr (sizeof(T) == sizeof(float)) {
      value = std::strtof(copy.c_str(), nullptr);
    } else {
      value = std::strtod(copy.c_str(), nullptr);
    }
  }
  return error == std::errc() || error == std::errc::result_out_of_range;
}

// Parse all of `text` as a decimal integer.
inline bool parseInteger(std::string_view text, int64_t& value) {
  if (text.starts_with('+') && !text.starts_with("+-")) text.remove_prefix(1);
  const char* last = text.data() + text.size();
  const auto [end, error] = std::from_chars(text.data(), last, value);
  return error == std::errc() && end == last && !text.empty();
}

}  // namespace iso::io
