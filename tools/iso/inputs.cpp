#include "tools/iso/inputs.h"

#include <algorithm>
#include <chrono>
#include <memory>

#include "iso/error.h"

namespace iso::cli {
namespace {

bool isPointFileName(const std::filesystem::path& path) {
  std::string name = path.filename().string();
  std::transform(name.begin(), name.end(), name.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  if (name.size() > 3 && name.ends_with(".gz")) name.resize(name.size() - 3);
  for (const char* ext : {".ply", ".las", ".laz", ".pcd", ".drc", ".e57", ".xyz", ".txt", ".pts",
                          ".csv", ".asc", ".neu", ".xyzrgb", ".xyzn"})
    if (name.ends_with(ext)) return true;
  return false;
}

nlohmann::json crsJson(const CoordinateSystem& crs) {
  nlohmann::json j = {{"source", crs.source}};
  if (!crs.wkt.empty()) j["wkt"] = crs.wkt;
  if (crs.epsg) j["epsg"] = *crs.epsg;
  if (crs.verticalEpsg) j["vertical_epsg"] = *crs.verticalEpsg;
  if (!crs.name.empty()) j["name"] = crs.name;
  return j;
}

// What the reader found and did: the input's entry in the report and the file's metadata.
nlohmann::json inputJson(const PointReader& reader, uint64_t points) {
  const PointFileInfo& info = reader.info();
  nlohmann::json input = {{"file", info.path.string()},
                          {"format", info.format},
                          {"points", points},
                          {"non_finite_dropped", reader.stats().droppedNonFinite}};
  if (info.crs) input["crs"] = crsJson(*info.crs);
  return input;
}

// "FILE: NOTE", or for several files "N files (FIRST, SECOND, ...): NOTE".
std::string noteOfFiles(const std::string& note, const std::vector<std::string>& paths) {
  if (paths.size() == 1) return paths[0] + ": " + note;
  constexpr size_t kNamed = 3;
  std::string names;
  for (size_t i = 0; i < std::min(paths.size(), kNamed); ++i)
    names += (i > 0 ? ", " : "") + paths[i];
  if (paths.size() > kNamed) names += ", ...";
  return std::to_string(paths.size()) + " files (" + names + "): " + note;
}

}  // namespace

std::vector<std::filesystem::path> expandInputs(const std::vector<std::string>& arguments) {
  std::vector<std::filesystem::path> files;
  for (const std::string& argument : arguments) {
    const std::filesystem::path path(argument);
    std::error_code error;
    if (std::filesystem::is_directory(path, error)) {
      std::vector<std::filesystem::path> found;
      for (const auto& entry : std::filesystem::directory_iterator(path))
        if (entry.is_regular_file() && isPointFileName(entry.path())) found.push_back(entry.path());
      if (found.empty()) throw FileError(argument, std::nullopt, "directory holds no point files");
      std::sort(found.begin(), found.end());
      files.insert(files.end(), found.begin(), found.end());
    } else {
      files.push_back(path);  // the reader reports a missing or unreadable file
    }
  }
  return files;
}

bool everyFileHas(const std::vector<std::filesystem::path>& files, const ReadOptions& options,
                  const std::string& name) {
  ReadOptions withExtras = options;
  withExtras.keepExtras = true;
  for (const auto& file : files) {
    const auto names = openPointFile(file, withExtras)->info().extraNames;
    if (std::find(names.begin(), names.end(), name) == names.end()) return false;
  }
  return true;
}

size_t extraIndex(const PointFileInfo& info, const std::string& name) {
  const auto& names = info.extraNames;
  const auto at = std::find(names.begin(), names.end(), name);
  if (at != names.end()) return size_t(at - names.begin());
  std::string all;
  for (const std::string& n : names) all += (all.empty() ? "" : ", ") + n;
  throw FileError(info.path, std::nullopt,
                  "has no scalar '" + name + "' (" +
                      (names.empty() ? std::string("it has none") : "it has: " + all) + ")");
}

ReadSummary readPoints(const std::vector<std::filesystem::path>& files, const ReadOptions& options,
                       ProgressReporter* progress,
                       const std::function<void(bool normals, bool colors)>& begin,
                       const std::function<void(const PointCloud&)>& add,
                       const std::string& scalar) {
  const auto started = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<PointReader>> readers;
  std::vector<size_t> scalarAt;  // per file: the index of `scalar` among its extras
  bool normals = true, colors = true;
  ReadOptions withExtras = options;
  withExtras.keepExtras = options.keepExtras || !scalar.empty();
  for (const auto& file : files) {
    readers.push_back(openPointFile(file, withExtras));
    if (!scalar.empty()) scalarAt.push_back(extraIndex(readers.back()->info(), scalar));
    normals = normals && readers.back()->info().hasNormals;
    colors = colors && readers.back()->info().hasColors;
  }
  ReadSummary summary;
  if (!normals && std::any_of(readers.begin(), readers.end(),
                              [](const auto& r) { return r->info().hasNormals; }))
    summary.notes.push_back("normals ignored: not every input has them");
  if (!colors && std::any_of(readers.begin(), readers.end(),
                             [](const auto& r) { return r->info().hasColors; }))
    summary.notes.push_back("colors ignored: not every input has them");
  if (progress != nullptr) {
    uint64_t declared = 0;
    for (const auto& reader : readers) {
      if (!reader->info().declaredPoints) {
        declared = 0;  // unknown for text files: no percent
        break;
      }
      declared += *reader->info().declaredPoints;
    }
    progress->begin("read", declared);
  }
  begin(normals, colors);
  // A note said of many files (the tiles of one scan) is said once.
  std::vector<std::pair<std::string, std::vector<std::string>>> filesOfNote;  // first said first
  PointCloud batch;
  for (auto& reader : readers) {
    uint64_t points = 0;
    for (;;) {
      batch.clear();
      if (reader->read(batch, 1u << 20) == 0) break;
      progressAdvance(batch.size());
      if (!normals) batch.normals.clear();
      if (!colors) batch.colors.clear();
      if (!scalar.empty()) {
        const size_t k = scalarAt[size_t(&reader - readers.data())], n = batch.extraCount();
        for (size_t i = 0; i < batch.size(); ++i) batch.extras[i] = batch.extras[i * n + k];
        batch.extras.resize(batch.size());
        batch.extraNames = {scalar};
      }
      points += batch.size();
      add(batch);
    }
    summary.nonFiniteDropped += reader->stats().droppedNonFinite;
    summary.inputs.push_back(inputJson(*reader, points));
    for (const std::string& note : reader->info().notes) {
      auto said = std::find_if(filesOfNote.begin(), filesOfNote.end(),
                               [&](const auto& entry) { return entry.first == note; });
      if (said == filesOfNote.end()) said = filesOfNote.insert(said, {note, {}});
      said->second.push_back(reader->info().path.string());
    }
    reader.reset();  // its file and buffers
  }
  for (const auto& [note, paths] : filesOfNote) summary.notes.push_back(noteOfFiles(note, paths));
  if (progress != nullptr) progress->end();
  summary.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return summary;
}

LoadedPoints loadPoints(const std::vector<std::filesystem::path>& files, const ReadOptions& options,
                        ProgressReporter* progress, const std::string& scalar) {
  LoadedPoints loaded;
  PointCloud& cloud = loaded.cloud;
  static_cast<ReadSummary&>(loaded) = readPoints(
      files, options, progress, [](bool, bool) {},
      [&](const PointCloud& batch) {
        const auto append = [](auto& to, const auto& from) {
          to.insert(to.end(), from.begin(), from.end());
        };
        append(cloud.positions, batch.positions);
        append(cloud.normals, batch.normals);
        append(cloud.colors, batch.colors);
        if (!scalar.empty()) {
          cloud.extraNames = {scalar};
          append(cloud.extras, batch.extras);
        }
      },
      scalar);
  return loaded;
}

}  // namespace iso::cli
