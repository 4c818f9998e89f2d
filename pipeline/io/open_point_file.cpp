// Choosing a reader for a point file: by content first, then by extension.
#include <algorithm>
#include <cctype>
#include <cstring>
#include <iterator>
#include <optional>
#include <string_view>

#include "iso/error.h"
#include "pipeline/io/input_stream.h"
#include "pipeline/io/point_readers.h"
#include "pipeline/io/readers.h"

namespace iso {
namespace {

constexpr const char* kSupportedFormats =
    "supported: PLY (.ply), LAS 1.0-1.4 (.las), PCD (.pcd), Draco (.drc), text (.xyz .txt .pts "
    ".csv .asc .neu .xyzrgb .xyzn, or any name with --columns), each optionally gzip-compressed "
    "(.gz); LAZ (.laz) and E57 (.e57)";

// Extensions always read as text (CloudCompare's ASCII cloud names among them).
constexpr std::string_view kTextExtensions[] = {".xyz", ".txt", ".pts",    ".csv",
                                                ".asc", ".neu", ".xyzrgb", ".xyzn"};

enum class Format : uint8_t { kPly, kLas, kDraco, kE57, kPcd, kText };

// Reservations follow the header's count only up to this many points, so that a hostile count
// cannot allocate more than the file's content justifies.
constexpr uint64_t kMaxReserve = uint64_t{1} << 22;
constexpr size_t kBatchPoints = size_t{1} << 20;

bool startsWith(std::span<const std::byte> bytes, std::string_view prefix) {
  return bytes.size() >= prefix.size() &&
         std::memcmp(bytes.data(), prefix.data(), prefix.size()) == 0;
}

}  // namespace

std::string io::lowercaseExtension(const std::filesystem::path& path) {
  const auto lower = [](std::string text) {
    std::transform(text.begin(), text.end(), text.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return text;
  };
  std::string extension = lower(path.extension().string());
  if (extension == ".gz") extension = lower(path.stem().extension().string());
  return extension;
}

namespace {

std::optional<Format> formatBySignature(io::InputStream& in) {
  const std::span<const std::byte> head = in.peek(8);
  if (startsWith(head, "ply\n") || startsWith(head, "ply\r\n")) return Format::kPly;
  if (startsWith(head, "LASF")) return Format::kLas;
  if (startsWith(head, "DRACO")) return Format::kDraco;
  if (startsWith(head, "ASTM-E57")) return Format::kE57;
  return std::nullopt;
}

// A file of an unknown extension that is not text: what was tried and why each failed.
[[noreturn]] void refuseUnknown(const io::InputStream& in, const std::string& extension,
                                const std::string& whyNotText) {
  const std::string what = extension.empty() ? "a name without extension" : "'" + extension + "'";
  throw FileError(
      in.name(), std::nullopt,
      "unknown point file format (" + what +
          "): it is not PLY (no 'ply' line first), LAS (no LASF signature), Draco (no DRACO "
          "signature), E57 (no ASTM-E57 signature) or PCD (no PCD header), nor text (" +
          whyNotText + "); " + kSupportedFormats);
}

// The format by signature, then by extension, then (a name of no known extension) by content.
Format chooseFormat(io::InputStream& in, const ReadOptions& options) {
  if (const std::optional<Format> format = formatBySignature(in)) return *format;
  const std::string extension = io::lowercaseExtension(in.path());
  if (extension == ".laz") throw FileError(in.name(), 0, "not a LAZ file: no LASF signature");
  if (extension == ".e57") throw FileError(in.name(), 0, "not an E57 file: no ASTM-E57 signature");
  if (extension == ".pcd" || io::looksLikePcd(in)) return Format::kPcd;
  if (!options.columns.empty()) return Format::kText;
  if (extension == ".ply")
    throw FileError(in.name(), 0, "not a PLY file: it does not start with 'ply'");
  if (extension == ".las") throw FileError(in.name(), 0, "not a LAS file: no LASF signature");
  if (extension == ".drc") throw FileError(in.name(), 0, "not a Draco file: no DRACO signature");
  if (std::find(std::begin(kTextExtensions), std::end(kTextExtensions), extension) !=
      std::end(kTextExtensions))
    return Format::kText;
  if (const std::optional<std::string> whyNot = io::whyNotText(in))
    refuseUnknown(in, extension, *whyNot);
  return Format::kText;
}

}  // namespace

std::unique_ptr<PointReader> openPointFile(const std::filesystem::path& path,
                                           const ReadOptions& options) {
  io::InputStream in(path);
  switch (chooseFormat(in, options)) {
    case Format::kPly:
      return io::makePlyReader(std::move(in), options);
    case Format::kLas:
      return io::makeLasReader(std::move(in), options);
    case Format::kDraco:
      return io::makeDracoReader(std::move(in));
    case Format::kE57:
      return io::makeE57Reader(std::move(in), options);
    case Format::kPcd:
      return io::makePcdReader(std::move(in), options.keepExtras);
    case Format::kText:
      break;
  }
  return io::makeTextReader(std::move(in), options);
}

PointCloud readPointFile(const std::filesystem::path& path, const ReadOptions& options,
                         ReadStats* stats) {
  const std::unique_ptr<PointReader> reader = openPointFile(path, options);
  PointCloud points;
  const uint64_t expected = std::min(reader->info().declaredPoints.value_or(0), kMaxReserve);
  points.positions.reserve(expected);
  if (reader->info().hasNormals) points.normals.reserve(expected);
  if (reader->info().hasColors) points.colors.reserve(expected);
  points.extras.reserve(expected * reader->info().extraNames.size());
  while (reader->read(points, kBatchPoints) > 0) {
  }
  if (stats != nullptr) *stats = reader->stats();
  return points;
}

}  // namespace iso
