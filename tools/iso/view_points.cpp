// Raw scans for `iso view --draw image` (view_points.h).
#include "tools/iso/view_points.h"

#include <fmt/core.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/reader.h"
#include "pipeline/output/keep_points.h"
#include "pipeline/points/viewing.h"

namespace iso::cli {
namespace {

constexpr size_t kBatch = size_t(1) << 20;  // points read at a time

using Clock = std::chrono::steady_clock;

// The files' frame: the points' bounds and centre, the scene's up (z for LiDAR) and the names.
viewer::ImageInputs frameOf(const PointStore& store, const ImageFiles& files) {
  viewer::ImageInputs in;
  for (const auto& reader : files.readers) {
    const std::string format = reader->info().format;
    if (format.rfind("las", 0) == 0 || format.rfind("laz", 0) == 0 || format.rfind("e57", 0) == 0)
      in.up = {0, 0, 1};  // LiDAR: z up
  }
  in.bounds = {store.lo(), store.hi()};
  in.origin = 0.5 * (store.lo() + store.hi());
  for (const auto& path : files.paths) in.names.push_back(path.string());
  // About kFramingPoints points for the default camera, each as wide as a cell of a grid of as
  // many cells over the bounds' largest side squared (a surface's spacing, roughly).
  const uint64_t stride = std::max<uint64_t>(1, store.size() / viewer::kFramingPoints);
  const glm::dvec3 extent = store.hi() - store.lo();
  const double size = std::max({extent.x, extent.y, extent.z, 1e-9}) /
                      std::sqrt(double(std::max<uint64_t>(store.size() / stride, 1)));
  for (const PointCloud& cloud : store.every(stride))
    for (const glm::dvec3& p : cloud.positions) in.framing.push_back({p, size});
  return in;
}

// `clouds` (one an object) prepared in `frame`: spacings and normals.
viewer::ImageInputs prepare(std::vector<PointCloud>&& clouds, const viewer::ImageInputs& frame) {
  viewer::ImageInputs in = frame;
  in.objects.clear();
  const glm::dvec3 extent = in.bounds.hi - in.bounds.lo;
  const float fallback = std::max(float(glm::length(extent)) * 0.01f, 1e-6f);
  for (PointCloud& cloud : clouds) {
    ViewingPoints v = prepareForViewing(std::move(cloud), in.origin, fallback);
    viewer::ImageObject o;
    o.positions = std::move(v.positions);
    o.normals = std::move(v.normals);
    o.colors = std::move(v.colors);
    o.spacings = std::move(v.spacings);
    o.spacing = v.spacing;
    o.orientedNormals = !v.normalsEstimated;
    in.normalsEstimated |= v.normalsEstimated;
    in.objects.push_back(std::move(o));
  }
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

uint64_t hostPointBudget() {
  const long pages = sysconf(_SC_PHYS_PAGES), pageSize = sysconf(_SC_PAGESIZE);
  const uint64_t memory = pages > 0 && pageSize > 0 ? uint64_t(pages) * uint64_t(pageSize)
                                                    : uint64_t(8) << 30;
  return std::clamp<uint64_t>(memory / 4 / 40, 1'000'000, UINT32_MAX);
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

ImagePoints readImagePoints(ImageFiles& files, const ImageLoad& load) {
  const auto start = Clock::now();
  const auto since = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  const uint64_t hostPoints = std::max<uint64_t>(load.hostPoints, 2);
  // Known counts are thinned while reading (a scan larger than memory need not be held whole);
  // unknown ones each time the points held reach hostPoints (every 2nd of them dropped).
  const uint64_t declared = files.declaredPoints.value_or(0);
  uint64_t stride = declared > hostPoints ? (declared + hostPoints - 1) / hostPoints : 1;
  ImagePoints points;
  uint64_t lastPreview = 0;
  PointCloud batch, kept;
  for (size_t f = 0; f < files.readers.size(); ++f) {
    points.store.add(f, PointCloud{});  // the object, even when it stays empty
    while (!(load.stop && load.stop->load())) {
      batch.clear();
      if (files.readers[f]->read(batch, kBatch) == 0) break;
      kept.clear();
      for (size_t i = 0; i < batch.size(); ++i, ++points.pointsRead)
        if (points.pointsRead % stride == 0) appendPoint(kept, batch, i);
      points.store.add(f, kept);
      if (points.store.size() >= hostPoints) {
        points.store.thin();
        stride *= 2;
      }
      const uint64_t held = points.store.size();
      if (load.preview && (lastPreview == 0 || held >= 2 * lastPreview)) {
        lastPreview = held;
        viewer::ImageInputs p =
            prepare(points.store.every((held + kPreviewPoints - 1) / kPreviewPoints),
                    frameOf(points.store, files));
        p.pointsRead = points.pointsRead;
        p.preview = true;
        p.loadSeconds = since();
        load.preview(std::move(p));
      }
    }
  }
  points.store.index();
  points.frame = frameOf(points.store, files);
  points.readSeconds = since();
  return points;
}

viewer::ImageInputs imageInputs(const ImagePoints& points, uint64_t maxPoints,
                                const PointView* view) {
  const auto start = Clock::now();
  const PointStore& store = points.store;
  maxPoints = std::max<uint64_t>(maxPoints, 1);
  std::string choice;
  std::vector<PointCloud> clouds;
  if (store.size() <= maxPoints) {
    clouds = store.every(1);
  } else if (view) {
    PointStore::Choice c;
    clouds = store.forView(*view, maxPoints, &c);
    choice = fmt::format("chosen for the view from {}: {} where it looks, fitting --vram",
                         points.pointsRead, c.seen);
  } else {
    clouds = store.every((store.size() + maxPoints - 1) / maxPoints);
    choice = fmt::format("a uniform subsample of {} that fits --vram", points.pointsRead);
  }
  viewer::ImageInputs in = prepare(std::move(clouds), points.frame);
  in.pointsRead = points.pointsRead;
  in.choice = std::move(choice);
  in.loadSeconds = points.readSeconds + std::chrono::duration<double>(Clock::now() - start).count();
  return in;
}

PointView pointViewOf(const viewer::Camera& camera, uint32_t width, uint32_t height) {
  PointView v;
  v.eye = camera.eye;
  v.forward = glm::normalize(camera.target - camera.eye);
  v.right = glm::normalize(glm::cross(v.forward, camera.up));
  v.up = glm::cross(v.right, v.forward);
  v.tanHalfHeight = std::tan(glm::radians(camera.fovDegrees) * 0.5);
  v.aspect = double(width) / double(std::max<uint32_t>(height, 1));
  v.height = std::max<uint32_t>(height, 1);
  return v;
}

viewer::ImageInputs readImageInputs(ImageFiles& files, const ImageLoad& load) {
  return imageInputs(readImagePoints(files, load), load.maxPoints);
}

}  // namespace iso::cli
