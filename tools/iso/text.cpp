#include "tools/iso/text.h"

#include <fmt/core.h>

#include <cmath>
#include <map>
#include <stdexcept>

#include <fstream>
#include <optional>

#include "iso/error.h"

namespace iso::cli {

std::string withSeparators(uint64_t value) {
  std::string digits = std::to_string(value);
  for (int i = static_cast<int>(digits.size()) - 3; i > 0; i -= 3) digits.insert(size_t(i), ",");
  return digits;
}

std::string humanBytes(uint64_t bytes) {
  static const char* const kUnits[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double value = static_cast<double>(bytes);
  int unit = 0;
  while (value >= 1024.0 && unit < 4) {
    value /= 1024.0;
    ++unit;
  }
  return unit == 0 ? fmt::format("{} B", bytes) : fmt::format("{:.1f} {}", value, kUnits[unit]);
}

std::string indentLines(const std::string& text, int columns) {
  std::string out;
  for (char c : text) {
    out += c;
    if (c == '\n') out.append(size_t(columns), ' ');
  }
  return out;
}

}  // namespace iso::cli

namespace iso::cli {

void writeTextFile(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::path temporary = path;
  temporary += ".tmp";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out << text;
    out.close();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temporary, ignored);
      throw FileError(path.string(), std::nullopt, "cannot write it");
    }
  }
  std::error_code error;
  std::filesystem::rename(temporary, path, error);
  if (error) {
    std::filesystem::remove(temporary, error);
    throw FileError(path.string(), std::nullopt, "cannot write it: " + error.message());
  }
}

uint64_t parseSize(const std::string& text, const char* option) {
  size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  const std::string unit = text.substr(used);
  const std::map<std::string, double> units = {
      {"", 1.0}, {"K", 1024.0}, {"M", 1048576.0}, {"G", 1073741824.0}, {"T", 1099511627776.0}};
  if (used == 0 || !units.contains(unit) || !(value > 0.0) || !std::isfinite(value))
    throw UsageError(std::string(option) +
                                " must be a size like 2G, 512M or 100000, not '" + text + "'");
  return uint64_t(value * units.at(unit));
}

}  // namespace iso::cli
