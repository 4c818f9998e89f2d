// Raw scans for `iso view --draw image` (view_points.h).
#include "tools/iso/view_points.h"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/reader.h"
#include "pipeline/output/keep_points.h"
#include "pipeline/points/viewing.h"

namespace iso::cli {
namespace {

constexpr size_t kBatch = size_t(1) << 20;  // points read at a time

using Clock = std::chrono::steady_clock;

// Every `stride`-th point of `clouds` (counting across them), as objects of one view: bounds,
// origin, spacings and normals. With `take` and a stride of 1 the clouds are moved, not copied.
viewer::ImageInputs prepare(std::vector<PointCloud>& clouds, const ImageFiles& files,
                            uint64_t stride, Clock::time_point start, bool take) {
  viewer::ImageInputs in;
  glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  std::vector<PointCloud> kept(clouds.size());
  uint64_t counter = 0;
  for (size_t f = 0; f < clouds.size(); ++f) {
    PointCloud& cloud = clouds[f];
    for (size_t i = 0; i < cloud.size(); ++i, ++counter) {
      if (counter % stride != 0) continue;
      lo = glm::min(lo, cloud.positions[i]);
      hi = glm::max(hi, cloud.positions[i]);
      if (!(take && stride == 1)) appendPoint(kept[f], cloud, i);
    }
    if (take && stride == 1) kept[f] = std::move(cloud);
  }
  for (const auto& reader : files.readers) {
    const std::string format = reader->info().format;
    if (format.rfind("las", 0) == 0 || format.rfind("laz", 0) == 0 || format.rfind("e57", 0) == 0)
      in.up = {0, 0, 1};  // LiDAR: z up
  }
  if (lo.x > hi.x) lo = hi = glm::dvec3(0.0);
  in.bounds = {lo, hi};
  in.origin = 0.5 * (lo + hi);
  const float fallback = std::max(float(glm::length(hi - lo)) * 0.01f, 1e-6f);
  for (size_t f = 0; f < kept.size(); ++f) {
    ViewingPoints v = prepareForViewing(std::move(kept[f]), in.origin, fallback);
    viewer::ImageObject o;
    o.positions = std::move(v.positions);
    o.normals = std::move(v.normals);
    o.colors = std::move(v.colors);
    o.spacings = std::move(v.spacings);
    o.spacing = v.spacing;
    o.orientedNormals = !v.normalsEstimated;
    in.normalsEstimated |= v.normalsEstimated;
    in.objects.push_back(std::move(o));
    in.names.push_back(files.paths[f].string());
  }
  in.loadSeconds = std::chrono::duration<double>(Clock::now() - start).count();
  return in;
}

// The kept points of an .iso file (iso convert --keep-points) as a point file: the points chunks
// of the level of detail that fits maxPoints (keptPointsCut), chunk after chunk.
class KeptPointsReader final : public PointReader {
 public:
  KeptPointsReader(const std::filesystem::path& path, uint64_t maxPoints)
      : reader_(Reader::open(path)), cut_(keptPointsCut(reader_, maxPoints)) {
    if (cut_.empty())
      throw FileError(path, std::nullopt,
                      "keeps no points to draw as image-space points (convert with "
                      "--keep-points, or view it without --draw image)");
    info_.path = path;
    // Scans of LiDAR (z up) name their reader's format first, as the readers' formats do.
    info_.format = "points kept in .iso";
    const auto meta = nlohmann::json::parse(reader_.metadata(), nullptr, false);
    if (meta.is_object() && meta.contains("inputs") && meta["inputs"].is_array())
      for (const auto& input : meta["inputs"])
        for (const char* lidar : {"las", "laz", "e57"})
          if (input.is_object() && input.value("format", "").rfind(lidar, 0) == 0)
            info_.format = std::string(lidar) + " points kept in .iso";
    uint64_t points = 0;
    for (uint32_t id : cut_) points += reader_.chunks()[id].pointCount;
    info_.declaredPoints = points;
    pending_ = decodeKeptPoints(reader_, cut_[0]);
    info_.hasNormals = pending_.hasNormals();
    info_.hasColors = pending_.hasColors();
  }
  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }
  size_t read(PointCloud& out, size_t maxPoints) override {
    size_t n = 0;
    while (n < maxPoints) {
      if (taken_ == pending_.size()) {
        if (++next_ >= cut_.size()) break;
        pending_ = decodeKeptPoints(reader_, cut_[next_]);
        taken_ = 0;
      }
      for (; taken_ < pending_.size() && n < maxPoints; ++taken_, ++n)
        appendPoint(out, pending_, taken_);
    }
    stats_.pointsRead += n;
    return n;
  }

 private:
  Reader reader_;
  std::vector<uint32_t> cut_;
  PointFileInfo info_;
  ReadStats stats_;
  PointCloud pending_;
  size_t next_ = 0, taken_ = 0;
};

}  // namespace

bool isIsoFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::array<char, 8> magic{};
  in.read(magic.data(), magic.size());
  return in.gcount() == 8 && std::equal(magic.begin(), magic.end(), kHeaderMagic.begin(),
                                        [](char a, uint8_t b) { return uint8_t(a) == b; });
}

ImageFiles openImageFiles(const std::vector<std::filesystem::path>& files, uint64_t maxPoints) {
  ImageFiles out;
  uint64_t declared = 0;
  bool known = true;
  for (const auto& file : files) {
    out.paths.push_back(file);
    if (file.extension() == ".iso" || isIsoFile(file))
      out.readers.push_back(std::make_unique<KeptPointsReader>(file, maxPoints));
    else
      out.readers.push_back(openPointFile(file));
    const auto& count = out.readers.back()->info().declaredPoints;
    known = known && count.has_value();
    if (count) declared += *count;
  }
  if (known) out.declaredPoints = declared;
  return out;
}

viewer::ImageInputs readImageInputs(ImageFiles& files, const ImageLoad& load) {
  const auto start = Clock::now();
  const uint64_t maxPoints = std::max<uint64_t>(load.maxPoints, 1);
  // Known counts subsample while reading (a 100M-point scan need not be held whole); unknown
  // ones after.
  const uint64_t declared = files.declaredPoints.value_or(0);
  const uint64_t readStride = declared > maxPoints ? (declared + maxPoints - 1) / maxPoints : 1;
  std::vector<PointCloud> clouds(files.readers.size());
  uint64_t read = 0, kept = 0, lastPreview = 0;
  PointCloud batch;
  for (size_t f = 0; f < files.readers.size(); ++f) {
    while (!(load.stop && load.stop->load())) {
      batch.clear();
      if (files.readers[f]->read(batch, kBatch) == 0) break;
      for (size_t i = 0; i < batch.size(); ++i, ++read)
        if (read % readStride == 0) appendPoint(clouds[f], batch, i);
      kept = 0;
      for (const PointCloud& c : clouds) kept += c.size();
      if (load.preview && (lastPreview == 0 || kept >= 2 * lastPreview)) {
        lastPreview = kept;
        viewer::ImageInputs p =
            prepare(clouds, files, (kept + kPreviewPoints - 1) / kPreviewPoints, start, false);
        p.pointsRead = read;
        p.preview = true;
        load.preview(std::move(p));
      }
    }
  }
  kept = 0;
  for (const PointCloud& c : clouds) kept += c.size();
  viewer::ImageInputs in =
      prepare(clouds, files, kept > maxPoints ? (kept + maxPoints - 1) / maxPoints : 1, start,
              true);
  in.pointsRead = read;
  return in;
}

}  // namespace iso::cli
