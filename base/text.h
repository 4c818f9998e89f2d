// Numbers and words as text, in one place for every part of the project: byte sizes and counts
// for people, numbers parsed without locales (std::from_chars), and the names of options' values
// (one table per enumeration, read by the command line, scene files and reports alike).
#pragma once

#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace iso {

// 512 → "512 B", 1536 → "1.5 KiB", 3 << 30 → "3.0 GiB" (binary units, one decimal).
inline std::string byteSize(uint64_t bytes) {
  static const char* const kUnits[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double value = double(bytes);
  int unit = 0;
  while (value >= 1024.0 && unit < 6) {
    value /= 1024.0;
    ++unit;
  }
  char text[32];
  if (unit == 0)
    std::snprintf(text, sizeof text, "%llu B", static_cast<unsigned long long>(bytes));
  else
    std::snprintf(text, sizeof text, "%.1f %s", value, kUnits[unit]);
  return text;
}

// 1234567 → "1,234,567".
inline std::string withSeparators(uint64_t value) {
  std::string digits = std::to_string(value);
  for (int i = int(digits.size()) - 3; i > 0; i -= 3) digits.insert(size_t(i), ",");
  return digits;
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

// `count` finite numbers separated by commas ("1,2.5,-3e2"); nullopt for anything else.
inline std::optional<std::vector<double>> parseNumberList(std::string_view text, size_t count) {
  std::vector<double> values;
  while (true) {
    const size_t comma = text.find(',');
    double value = 0.0;
    if (!parseNumber(text.substr(0, comma), value) || !std::isfinite(value)) return std::nullopt;
    values.push_back(value);
    if (comma == std::string_view::npos) break;
    text.remove_prefix(comma + 1);
  }
  if (values.size() != count) return std::nullopt;
  return values;
}

namespace detail {
// The power of 1024 of a byte size's unit ("2G", "2g", "2GB", "2GiB": 3), removed from `text`;
// 0 when there is none.
inline int takeByteUnit(std::string_view& text) {
  static constexpr std::string_view kUnits = "KMGT";
  const auto unitAt = [&](size_t fromEnd) {
    if (text.size() <= fromEnd) return std::string_view::npos;
    return kUnits.find(
        char(std::toupper(static_cast<unsigned char>(text[text.size() - 1 - fromEnd]))));
  };
  for (std::string_view suffix : {"iB", "B", "ib", "b"})
    if (text.ends_with(suffix) && unitAt(suffix.size()) != std::string_view::npos) {
      text.remove_suffix(suffix.size());
      break;
    }
  const size_t unit = unitAt(0);
  if (unit == std::string_view::npos) return 0;
  text.remove_suffix(1);
  return int(unit) + 1;
}
}  // namespace detail

// A byte size such as "2G", "512M", "1.5G" or "100000": a decimal number and an optional binary
// unit K, M, G or T (either case, also written KB or KiB; all are powers of 1024). Whole numbers
// of bytes are exact up to 2^64 − 1; a fraction is rounded down to whole bytes. nullopt when the
// text is not one, is below one byte (zero, negative) or is more than 2^64 − 1 bytes once the unit
// is applied; the reason is then in *why, when given.
inline std::optional<uint64_t> parseByteSize(std::string_view text, std::string* why = nullptr) {
  const auto refuse = [&](const char* reason) -> std::optional<uint64_t> {
    if (why != nullptr) *why = reason;
    return std::nullopt;
  };
  constexpr const char* kTooLarge = "more than 2^64 − 1 bytes (16 EiB)";
  const int shift = 10 * detail::takeByteUnit(text);
  if (text.size() > 1 && text[0] == '+' &&
      (std::isdigit(static_cast<unsigned char>(text[1])) || text[1] == '.'))
    text.remove_prefix(1);
  uint64_t whole = 0;  // whole numbers are read exactly
  const char* last = text.data() + text.size();
  const auto [end, error] = std::from_chars(text.data(), last, whole);
  if (end == last && !text.empty()) {
    if (error == std::errc::result_out_of_range || (shift > 0 && whole > (~uint64_t{0} >> shift)))
      return refuse(kTooLarge);
    if (whole == 0) return refuse("not positive");
    return whole << shift;
  }
  double value = 0.0;
  if (text.starts_with('+') || !parseNumber(text, value) || std::isnan(value))
    return refuse("not a number with an optional unit K, M, G or T");
  if (!(value > 0.0)) return refuse("not positive");
  const double bytes = std::ldexp(value, shift);
  if (!(bytes < 18446744073709551616.0)) return refuse(kTooLarge);  // 2^64
  if (bytes < 1.0) return refuse("less than one byte");
  return uint64_t(bytes);
}

// The names of an enumeration's values: one table per enumeration, listing every value.
template <typename E>
struct Named {
  std::string_view name;
  E value;
};
template <typename E, size_t N>
using NameTable = std::array<Named<E>, N>;

template <typename E, size_t N>
constexpr std::string_view nameOf(const NameTable<E, N>& table, E value) {
  for (const Named<E>& entry : table)
    if (entry.value == value) return entry.name;
  return "?";
}

template <typename E, size_t N>
constexpr std::optional<E> valueNamed(const NameTable<E, N>& table, std::string_view name) {
  for (const Named<E>& entry : table)
    if (entry.name == name) return entry.value;
  return std::nullopt;
}

// "a, b or c".
template <typename E, size_t N>
std::string namesOf(const NameTable<E, N>& table) {
  std::string text;
  for (size_t i = 0; i < N; ++i)
    text += std::string(i == 0 ? "" : (i + 1 == N ? " or " : ", ")) + std::string(table[i].name);
  return text;
}

// The names alone, for command-line checks (CLI::IsMember).
template <typename E, size_t N>
std::vector<std::string> namesList(const NameTable<E, N>& table) {
  std::vector<std::string> names;
  for (const Named<E>& entry : table) names.emplace_back(entry.name);
  return names;
}

}  // namespace iso
