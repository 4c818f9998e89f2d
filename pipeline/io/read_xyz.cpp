// The reader of XYZ-like text files (.xyz .txt .pts .csv): one point per line, numbers separated by
// blanks, commas or semicolons, in the columns of ReadOptions::columns or guessed from their count.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "iso/error.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/point_readers.h"
#include "pipeline/io/text_fields.h"

namespace iso::io {
namespace {

enum Slot : int8_t { kSkip = -1, kX, kY, kZ, kNx, kNy, kNz, kRed, kGreen, kBlue, kSlotCount };
constexpr std::array<std::string_view, kSlotCount> kSlotNames = {"x",  "y", "z", "nx", "ny",
                                                                 "nz", "r", "g", "b"};

struct ColumnSpec {
  std::vector<Slot> columns;  // the slot of each column
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
    if (name != "_" && known == kSlotNames.end())
      fail(fmt::format("unknown column '{}' (known: x,y,z,nx,ny,nz,r,g,b and _ to skip)", name));
    const Slot slot = name == "_" ? kSkip : static_cast<Slot>(known - kSlotNames.begin());
    if (slot != kSkip &&
        std::find(spec.columns.begin(), spec.columns.end(), slot) != spec.columns.end())
      fail(fmt::format("column '{}' appears twice", name));
    spec.columns.push_back(slot);
  }
  if (!hasAll(spec.columns, kX)) fail("x, y and z are required");
  spec.hasNormals = hasAll(spec.columns, kNx);
  spec.hasColors = hasAll(spec.columns, kRed);
  if (hasAny(spec.columns, kNx) && !spec.hasNormals) fail("give all of nx,ny,nz or none");
  if (hasAny(spec.columns, kRed) && !spec.hasColors) fail("give all of r,g,b or none");
  return spec;
}

ColumnSpec guessColumns(const InputStream& in, size_t count) {
  switch (count) {
    case 3:
      return parseColumnSpec(in, "x,y,z");
    case 6:
      return parseColumnSpec(in, "x,y,z,nx,ny,nz");
    case 9:
      return parseColumnSpec(in, "x,y,z,nx,ny,nz,r,g,b");
    default:
      in.failLine(fmt::format(
          "cannot guess the meaning of {} columns (known: 3 = x,y,z; 6 = with normals; 9 = with "
          "normals and r,g,b): give them with --columns, e.g. x,y,z,_,r,g,b",
          count));
  }
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

class TextPointReader final : public PointReader {
 public:
  TextPointReader(InputStream in, const ReadOptions& options) : in_(std::move(in)) {
    info_.path = in_.path();
    info_.format = "xyz";
    if (!options.columns.empty()) spec_ = parseColumnSpec(in_, options.columns);
    findFirstDataLine();
    if (hasPendingLine_) {
      const std::vector<std::string_view> fields = splitFields(pendingLine_);
      if (options.columns.empty()) spec_ = guessColumns(in_, fields.size());
      colorFullScale_ = firstLineColorScale(fields);
    }
    info_.hasNormals = spec_.hasNormals;
    info_.hasColors = spec_.hasColors;
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

  // Colors are 0–255 when any color value of the first data line exceeds 1, else 0–1.
  double firstLineColorScale(const std::vector<std::string_view>& fields) const {
    for (size_t column = 0; column < std::min(fields.size(), spec_.columns.size()); ++column) {
      double value = 0.0;
      if (spec_.columns[column] >= kRed && parseNumber(fields[column], value) && value > 1.0)
        return 255.0;
    }
    return 1.0;
  }

  // Parse a data line; false when its point was dropped for a non-finite coordinate.
  bool parseLine(std::string_view line, PointCloud& out) {
    std::array<double, kSlotCount> values{};
    std::string_view field;
    size_t column = 0;
    for (; nextField<isBlankCommaOrSemicolon>(line, field); ++column) {
      if (column >= spec_.columns.size() || spec_.columns[column] == kSkip) continue;
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
  PointFileInfo info_;
  ReadStats stats_;
};

}  // namespace

std::unique_ptr<PointReader> makeTextReader(InputStream in, const ReadOptions& options) {
  return std::make_unique<TextPointReader>(std::move(in), options);
}

}  // namespace iso::io
