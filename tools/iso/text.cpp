#include "tools/iso/text.h"

#include <optional>
#include <vector>

#include "iso/atomic_file.h"
#include "iso/error.h"

namespace iso::cli {

std::string indentLines(const std::string& text, int columns) {
  std::string out;
  for (char c : text) {
    out += c;
    if (c == '\n') out.append(size_t(columns), ' ');
  }
  return out;
}

std::string describeCoordinateSystem(const nlohmann::json& crs) {
  // Written for any metadata: a key of another type than the one iso writes is left out.
  const auto number = [&](const char* key) {
    return crs.contains(key) && crs[key].is_number_unsigned() ? crs[key].get<uint64_t>()
                                                              : std::optional<uint64_t>();
  };
  const auto text = [&](const char* key) {
    return crs.contains(key) && crs[key].is_string() ? crs[key].get<std::string>() : "";
  };
  std::vector<std::string> parts;
  if (const auto epsg = number("epsg")) parts.push_back("EPSG:" + std::to_string(*epsg));
  if (const auto vertical = number("vertical_epsg"))
    parts.push_back("vertical EPSG:" + std::to_string(*vertical));
  if (!text("name").empty()) parts.push_back("\"" + text("name") + "\"");
  if (!text("wkt").empty())
    parts.push_back("OGC WKT (" + withSeparators(text("wkt").size()) + " characters)");
  if (!text("input").empty()) parts.push_back("from " + text("input"));
  std::string line;
  for (const std::string& part : parts) line += (line.empty() ? "" : ", ") + part;
  return line;
}

void writeTextFile(const std::filesystem::path& path, const std::string& text) {
  AtomicFile file(path);
  file.write(std::string_view(text));
  file.commit();
}

uint64_t parseSize(const std::string& text, const char* option) {
  std::string why;
  if (const std::optional<uint64_t> bytes = parseByteSize(text, &why)) return *bytes;
  throw UsageError(std::string(option) + " '" + text + "': " + why +
                   "; give a size like 2G, 512M or 100000 (units K, M, G, T: powers of 1024)");
}

}  // namespace iso::cli
