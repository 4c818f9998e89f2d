#include "tools/iso/text.h"

#include <optional>

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
