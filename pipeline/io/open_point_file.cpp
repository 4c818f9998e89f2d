// Choosing a reader for a point file: by content first, then by extension.
#include <algorithm>
#include <cctype>
#include <cstring>

#include "iso/error.h"
#include "pipeline/io/input_stream.h"
#include "pipeline/io/point_readers.h"
#include "pipeline/io/readers.h"

namespace iso {
namespace {

constexpr const char* kSupportedFormats =
    "supported: PLY (.ply), LAS 1.0-1.4 (.las), PCD (.pcd), Draco (.drc), text (.xyz .txt .pts "
    ".csv), each optionally "
    "gzip-compressed (.gz)";

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

std::unique_ptr<PointReader> openPointFile(const std::filesystem::path& path,
                                           const ReadOptions& options) {
  io::InputStream in(path);
  const std::span<const std::byte> head = in.peek(5);
  if (startsWith(head, "ply\n") || startsWith(head, "ply\r\n"))
    return io::makePlyReader(std::move(in), options);
  if (startsWith(head, "LASF")) return io::makeLasReader(std::move(in));
  if (startsWith(head, "DRACO")) return io::makeDracoReader(std::move(in));
  const std::string extension = io::lowercaseExtension(path);
  if (extension == ".laz") throw FileError(in.name(), std::nullopt, io::kLazNotSupported);
  if (extension == ".ply")
    throw FileError(in.name(), 0, "not a PLY file: it does not start with 'ply'");
  if (extension == ".las") throw FileError(in.name(), 0, "not a LAS file: no LASF signature");
  if (extension == ".pcd") return io::makePcdReader(std::move(in));
  if (extension == ".drc") throw FileError(in.name(), 0, "not a Draco file: no DRACO signature");
  if (extension == ".xyz" || extension == ".txt" || extension == ".pts" || extension == ".csv")
    return io::makeTextReader(std::move(in), options);
  const std::string what = extension.empty() ? "a name without extension" : "'" + extension + "'";
  throw FileError(in.name(), std::nullopt,
                  "unknown point file format: " + what + " (" + kSupportedFormats + ")");
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
