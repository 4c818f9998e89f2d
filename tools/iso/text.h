// Text for the command line: sizes and names of options checked, text files written (numbers
// and names themselves: base/text.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include "iso/error.h"
#include "base/text.h"

namespace iso::cli {

// Bytes from "2G", "512M", "1.5G", "100000" (binary units; parseByteSize); otherwise a UsageError
// naming the option, the value and what is wrong with it.
uint64_t parseSize(const std::string& text, const char* option);
// The value named `text` in `table`; UsageError naming the option and the accepted names (after
// `others`, names the caller accepts itself) otherwise.
template <typename E, size_t N>
E named(const NameTable<E, N>& table, const std::string& text, const char* option,
        const std::string& others = "") {
  if (const std::optional<E> value = valueNamed(table, text)) return *value;
  throw UsageError(std::string(option) + " must be " + others + namesOf(table) + ", not '" + text +
                   "'");
}
std::string indentLines(const std::string& text, int columns);  // indent every line but the first

// A coordinate system of a file's metadata (coordinateSystemOf) in a line: its EPSG codes, name,
// WKT size and input, e.g. `EPSG:32612 "WGS 84 / UTM zone 12N", OGC WKT (412 characters), from
// a.las`.
std::string describeCoordinateSystem(const nlohmann::json& crs);

// Write text to a file atomically (a temporary file renamed into place); throws iso::FileError.
void writeTextFile(const std::filesystem::path& path, const std::string& text);

}  // namespace iso::cli
