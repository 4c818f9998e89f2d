// The reader of XYZ-like text files (.xyz .txt .pts .csv .asc .neu .xyzrgb .xyzn, and others whose
// content is text): one point per line, numbers separated by blanks, commas or semicolons, in the
// columns of ReadOptions::columns or guessed from their count, values and the extension; and the
// check that tells a text point file by its content (whyNotText).
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "iso/error.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/point_readers.h"
#include "pipeline/io/text_fields.h"

namespace iso::io {
namespace {

// Rows sampled at the start of a file to guess its columns and color scale.
constexpr size_t kSampleRows = 100;
constexpr size_t kSampleBytes = size_t{64} << 10;

enum Slot : int8_t { kValue = -2, kSkip = -1, kX, kY, kZ, kNx, kNy, kNz, kRed, kGreen, kBlue, kSlotCount };
constexpr std::array<std::string_view, kSlotCount> kSlotNames = {"x",  "y", "z", "nx", "ny",
                                                                 "nz", "r", "g", "b"};

struct ColumnSpec {
  std::vector<Slot> columns;  // the slot of each column
  std::vector<std::string> valueNames;  // the names of the kValue columns, in order
  bool hasNormals = false;
  bool hasColors = false;
};

bool hasAll(const std::vector<Slot>& columns, Slot first) {
  for (int slot = first; slot < first + 3; ++slot)
    if (std::find(columns.begin(), columns.end(), slot) == columns.end()) return false;
  return true;
}

bool hasAny(const std::vector<Slot>& columns, Slot first) {
  return std::any_of(columns.begin(), columns.end(),
                     [&](Slot slot) { return slot >= first && slot < first + 3; });
}

ColumnSpec parseColumnSpec(const InputStream& in, std::string_view text) {
  const auto fail = [&](const std::string& why) {
    throw FileError(in.name(), std::nullopt, fmt::format("column spec '{}': {}", text, why));
  };
  ColumnSpec spec;
  std::string_view rest = text;
  std::string_view name;
  while (nextField<isBlankCommaOrSemicolon>(rest, name)) {
    const auto* known = std::find(kSlotNames.begin(), kSlotNames.end(), name);
    // Another name of letters, digits and _ (not first a digit) names a value column.
    const bool isName = !name.empty() && std::isdigit(static_cast<unsigned char>(name[0])) == 0 &&
                        std::all_of(name.begin(), name.end(), [](char c) {
                          return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_';
                        });
    if (name != "_" && known == kSlotNames.end() && !isName)
      fail(fmt::format("unknown column '{}' (known: x,y,z,nx,ny,nz,r,g,b, _ to skip, and names "
                       "of values: letters, digits and _)",
                       name));
    const Slot slot = name == "_"                  ? kSkip
                      : known == kSlotNames.end() ? kValue
                                                   : static_cast<Slot>(known - kSlotNames.begin());
    if ((slot >= 0 &&
         std::find(spec.columns.begin(), spec.columns.end(), slot) != spec.columns.end()) ||
        (slot == kValue && std::find(spec.valueNames.begin(), spec.valueNames.end(), name) !=
                               spec.valueNames.end()))
      fail(fmt::format("column '{}' appears twice", name));
    if (slot == kValue) spec.valueNames.emplace_back(name);
    spec.columns.push_back(slot);
  }
  if (!hasAll(spec.columns, kX)) fail("x, y and z are required");
  spec.hasNormals = hasAll(spec.columns, kNx);
  spec.hasColors = hasAll(spec.columns, kRed);
  if (hasAny(spec.columns, kNx) && !spec.hasNormals) fail("give all of nx,ny,nz or none");
  if (hasAny(spec.columns, kRed) && !spec.hasColors) fail("give all of r,g,b or none");
  return spec;
}

// Whether the three columns from `first` hold 0–255 colors in every sampled row, some above 1 (a
// unit normal has no component above 1).
bool looksLikeColors(const std::vector<std::vector<double>>& rows, size_t first) {
  bool isAboveOne = false;
  for (const std::vector<double>& row : rows)
    for (size_t column = first; column < first + 3; ++column) {
      if (!(row[column] >= 0.0 && row[column] <= 255.0)) return false;
      isAboveOne = isAboveOne || row[column] > 1.0;
    }
  return isAboveOne;
}

// The columns of a file without a spec, from the count of its first rows and, where the count
// leaves a choice, from their values and the extension (specs/pipeline.md §19).
std::string guessColumns(const InputStream& in, const std::vector<std::vector<double>>& rows) {
  const std::string extension = lowercaseExtension(in.path());
  switch (rows.front().size()) {
    case 3:
      return "x,y,z";
    case 4:
      return "x,y,z,_";
    case 6:
      if (extension == ".xyzrgb" || (extension != ".xyzn" && looksLikeColors(rows, 3)))
        return "x,y,z,r,g,b";
      return "x,y,z,nx,ny,nz";
    case 7:
      if (looksLikeColors(rows, 4)) return "x,y,z,_,r,g,b";
      break;
    case 9:
      if (looksLikeColors(rows, 3) && !looksLikeColors(rows, 6)) return "x,y,z,r,g,b,nx,ny,nz";
      return "x,y,z,nx,ny,nz,r,g,b";
    default:
      break;
  }
  in.failLine(fmt::format(
      "cannot guess the meaning of {} columns (known: 3 = x,y,z; 4 = x,y,z and a value not read; "
      "6 = with normals, or r,g,b of 0-255; 7 = x,y,z, a value, r,g,b of 0-255; 9 = with normals "
      "and r,g,b): give them with --columns, e.g. x,y,z,_,r,g,b",
      rows.front().size()));
}

bool isCommentOrBlank(std::string_view line) {
  const size_t start = line.find_first_not_of(" \t\r\f\v");
  if (start == std::string_view::npos) return true;
  line.remove_prefix(start);
  return line.starts_with('#') || line.starts_with("//");
}

std::vector<std::string_view> splitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  std::string_view field;
  while (nextField<isBlankCommaOrSemicolon>(line, field)) fields.push_back(field);
  return fields;
}

// The numbers of a line; false when a field is not one.
bool parseRow(std::string_view line, std::vector<double>& row) {
  row.clear();
  std::string_view field;
  while (nextField<isBlankCommaOrSemicolon>(line, field)) {
    double value = 0.0;
    if (!parseNumber(field, value)) return false;
    row.push_back(value);
  }
  return true;
}

// Rows of numbers to guess the columns from: the first data line (NaN where it is not numbers, so
// that reading it names the field) and the rows of as many numbers that follow it in the stream's
// buffer (peeked, not read), up to kSampleRows.
std::vector<std::vector<double>> sampleRows(InputStream& in, std::string_view first) {
  std::vector<double> row;
  if (!parseRow(first, row))
    row.assign(splitFields(first).size(), std::numeric_limits<double>::quiet_NaN());
  std::vector<std::vector<double>> rows = {row};
  const std::span<const std::byte> bytes = in.peek(kSampleBytes);
  std::string_view rest(reinterpret_cast<const char*>(bytes.data()),
                        std::min(bytes.size(), kSampleBytes));
  while (rows.size() < kSampleRows) {
    const size_t end = rest.find('\n');
    if (end == std::string_view::npos) break;
    const std::string_view line = rest.substr(0, end);
    rest.remove_prefix(end + 1);
    if (isCommentOrBlank(line)) continue;
    if (!parseRow(line, row) || row.size() != rows.front().size()) break;
    rows.push_back(row);
  }
  return rows;
}

class TextPointReader final : public PointReader {
 public:
  TextPointReader(InputStream in, const ReadOptions& options) : in_(std::move(in)) {
    info_.path = in_.path();
    info_.format = "xyz";
    if (!options.columns.empty()) spec_ = parseColumnSpec(in_, options.columns);
    findFirstDataLine();
    if (hasPendingLine_) {
      const std::vector<std::vector<double>> rows = sampleRows(in_, pendingLine_);
      if (options.columns.empty()) {
        const std::string guessed = guessColumns(in_, rows);
        spec_ = parseColumnSpec(in_, guessed);
        if (rows.front().size() > 3)
          info_.notes.push_back(fmt::format(
              "its columns are taken as {} (guessed from its first lines; --columns says others)",
              guessed));
      }
      colorFullScale_ = colorScale(rows);
    }
    info_.hasNormals = spec_.hasNormals;
    info_.hasColors = spec_.hasColors;
    if (options.keepExtras) info_.extraNames = spec_.valueNames;
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    size_t appended = 0;
    std::string_view line;
    while (appended < maxPoints) {
      if (hasPendingLine_) {
        hasPendingLine_ = false;
        line = pendingLine_;
      } else if (!in_.readLine(line)) {
        break;
      } else if (isCommentOrBlank(line)) {
        continue;
      }
      appended += parseLine(line, out) ? 1 : 0;
    }
    stats_.pointsRead += appended;
    return appended;
  }

 private:
  // Find the first line of numbers, past comments, a .pts count line (a single integer) and a
  // line of column names (no field a number), and keep it for read().
  void findFirstDataLine() {
    std::string_view line;
    bool mayBeCount = true;
    while (in_.readLine(line)) {
      if (isCommentOrBlank(line)) continue;
      const std::vector<std::string_view> fields = splitFields(line);
      int64_t count = 0;
      if (mayBeCount && fields.size() == 1 && parseInteger(fields[0], count) && count >= 0) {
        info_.declaredPoints = static_cast<uint64_t>(count);
        mayBeCount = false;
        continue;
      }
      mayBeCount = false;
      double number = 0.0;
      const bool isColumnNames = std::none_of(
          fields.begin(), fields.end(), [&](auto field) { return parseNumber(field, number); });
      if (isColumnNames && !hasSkippedColumnNames_) {
        hasSkippedColumnNames_ = true;
        continue;
      }
      pendingLine_ = line;
      hasPendingLine_ = true;
      return;
    }
  }

  // Colors are 0–255 when any color value of the sampled rows exceeds 1, else 0–1.
  double colorScale(const std::vector<std::vector<double>>& rows) const {
    for (const std::vector<double>& row : rows)
      for (size_t column = 0; column < std::min(row.size(), spec_.columns.size()); ++column)
        if (spec_.columns[column] >= kRed && row[column] > 1.0) return 255.0;
    return 1.0;
  }

  // Parse a data line; false when its point was dropped for a non-finite coordinate.
  bool parseLine(std::string_view line, PointCloud& out) {
    std::array<double, kSlotCount> values{};
    const size_t extras = info_.extraNames.size();
    lineValues_.assign(extras, 0.0);
    std::string_view field;
    size_t column = 0, value = 0;
    for (; nextField<isBlankCommaOrSemicolon>(line, field); ++column) {
      if (column < spec_.columns.size() && spec_.columns[column] == kValue && extras > 0 &&
          !parseNumber(field, lineValues_[value++]))
        in_.failLine(fmt::format("column {} ({}) is not a number: '{}'", column + 1,
                                 info_.extraNames[value - 1], field));
      if (column >= spec_.columns.size() || spec_.columns[column] < 0) continue;
      if (!parseNumber(field, values[spec_.columns[column]]))
        in_.failLine(fmt::format("column {} ({}) is not a number: '{}'", column + 1,
                                 kSlotNames[spec_.columns[column]], field));
    }
    if (column != spec_.columns.size())
      in_.failLine(fmt::format("expected {} numbers, found {}", spec_.columns.size(), column));
    const glm::dvec3 position{values[kX], values[kY], values[kZ]};
    if (!isFinite(position)) {
      ++stats_.droppedNonFinite;
      return false;
    }
    out.positions.push_back(position);
    if (extras > 0) {
      out.extraNames = info_.extraNames;
      out.extras.insert(out.extras.end(), lineValues_.begin(), lineValues_.end());
    }
    if (spec_.hasNormals)
      out.normals.emplace_back(narrowToFloat(values[kNx]), narrowToFloat(values[kNy]),
                               narrowToFloat(values[kNz]));
    if (spec_.hasColors)
      out.colors.emplace_back(linearFromSrgbScaled(values[kRed], colorFullScale_),
                              linearFromSrgbScaled(values[kGreen], colorFullScale_),
                              linearFromSrgbScaled(values[kBlue], colorFullScale_));
    return true;
  }

  InputStream in_;
  ColumnSpec spec_;
  std::string pendingLine_;
  bool hasPendingLine_ = false;
  bool hasSkippedColumnNames_ = false;
  double colorFullScale_ = 1.0;
  std::vector<double> lineValues_;  // the value columns of the line being parsed (keepExtras)
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::optional<std::string> whyNotText(InputStream& in) {
  const std::span<const std::byte> bytes = in.peek(kSampleBytes);
  const std::string_view head(reinterpret_cast<const char*>(bytes.data()),
                              std::min(bytes.size(), kSampleBytes));
  if (head.empty()) return "the file is empty";
  if (const size_t zero = head.find('\0'); zero != std::string_view::npos)
    return fmt::format("byte {} is 0: binary data, not text", zero);
  const bool isWhole = bytes.size() <= kSampleBytes;  // else the last line may be cut
  std::string_view rest = head;
  size_t columns = 0, rows = 0, columnsLine = 0;
  bool mayBeCount = true, mayBeHeader = true;
  for (size_t number = 1; !rest.empty() && rows < kSampleRows; ++number) {
    const size_t end = rest.find('\n');
    if (end == std::string_view::npos && !isWhole) break;
    const std::string_view line = rest.substr(0, end);
    rest.remove_prefix(end == std::string_view::npos ? rest.size() : end + 1);
    if (isCommentOrBlank(line)) continue;
    const std::vector<std::string_view> fields = splitFields(line);
    double value = 0.0;
    const auto isNumber = [&](std::string_view field) { return parseNumber(field, value); };
    const size_t numbers = size_t(std::count_if(fields.begin(), fields.end(), isNumber));
    if (std::exchange(mayBeCount, false) && fields.size() == 1 && numbers == 1) continue;
    if (std::exchange(mayBeHeader, false) && numbers == 0) continue;  // column names
    if (numbers < fields.size()) {
      const auto field = *std::find_if_not(fields.begin(), fields.end(), isNumber);
      return fmt::format("line {}: '{:.40}' is not a number", number, field);
    }
    if (fields.size() < 3)
      return fmt::format("line {} has {} number{}, fewer than x, y and z", number, fields.size(),
                         fields.size() == 1 ? "" : "s");
    if (rows > 0 && fields.size() != columns)
      return fmt::format("line {} has {} numbers, line {} has {}", number, fields.size(),
                         columnsLine, columns);
    columns = fields.size();
    columnsLine = number;
    ++rows;
  }
  if (rows == 0) return fmt::format("no line of numbers in its first {} bytes", head.size());
  return std::nullopt;
}

std::unique_ptr<PointReader> makeTextReader(InputStream in, const ReadOptions& options) {
  return std::make_unique<TextPointReader>(std::move(in), options);
}

}  // namespace iso::io
