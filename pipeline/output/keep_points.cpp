// Points chunks from the input points, and back (specs/pipeline.md §17, "Keeping the points").
#include "pipeline/output/keep_points.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <limits>
#include <numbers>
#include <optional>
#include <queue>
#include <stdexcept>

#include "iso/error.h"
#include "iso/reader.h"
#include "iso/surface.h"
#include "iso/writer.h"
#include "pipeline/base/progress.h"
#include "pipeline/io/color.h"
#include "pipeline/outofcore/spill.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

constexpr size_t kBatchChunks = 16;  // chunks encoded in parallel at a time

struct EncodedChunk {
  ChunkDesc desc;
  std::vector<std::byte> data;
  std::optional<PointValues> values;  // in the order the data gives the points
  bool coarser = false;
  double maxError = 0.0;
};

}  // namespace

nlohmann::json KeptPointsStats::json() const {
  return {{"chunks", chunks},
          {"points", points},
          {"subsample_chunks", subsampleChunks},
          {"subsample_points", subsamplePoints},
          {"radii_from_conversion", radiiFromConversion},
          {"bytes", bytes},
          {"bytes_per_point", points > 0 ? double(bytes) / double(points) : 0.0},
          {"step_bits", stepBits},
          {"coarser_chunks", coarserChunks},
          {"max_error", maxError},
          {"values", valuesName.empty() ? nlohmann::json()
                                        : nlohmann::json{{"name", valuesName},
                                                         {"chunks", valuesChunks},
                                                         {"bytes", valuesBytes}}}};
}

PointsChunkWriter::PointsChunkWriter(Writer& writer, const FileHeader& header, int stepBits,
                                     bool colors, bool normals, uint32_t perChunk,
                                     const PointSet* prepared, KeptValues values, bool volume)
    : writer_(writer),
      frame_(header.frame),
      finest_(header.maxLevel),
      stepBits_(stepBits),
      colors_(colors),
      normals_(normals || (prepared != nullptr && !prepared->normal.empty())),
      perChunk_(std::clamp<uint32_t>(perChunk, 1, kMaxPointsPerChunk)),
      prepared_(prepared != nullptr && prepared->size() > 0 ? prepared : nullptr),
      values_(std::move(values)),
      volume_(volume) {
  stats_.stepBits = stepBits;
  stats_.valuesName = values_.name;
}

PointsChunkWriter::~PointsChunkWriter() = default;

float PointsChunkWriter::preparedMatch(uint64_t key, const glm::dvec3& world, glm::vec3& normal) {
  if (prepared_ == nullptr) return 0.0f;
  const SpillVector<uint64_t>& keys = prepared_->key;
  const size_t n = keys.size();
  if (cursor_ > 0 && cursor_ <= n && keys[cursor_ - 1] >= key) {  // not in key order: search
    size_t lo = 0, hi = n;
    while (lo < hi) {
      const size_t mid = lo + (hi - lo) / 2;
      if (keys[mid] < key)
        lo = mid + 1;
      else
        hi = mid;
    }
    cursor_ = lo;
  }
  while (cursor_ < n && keys[cursor_] < key) ++cursor_;
  // The prepared point of this key nearest to the point (merged duplicates: at it).
  const glm::vec3 u(toFrame(world, frame_));
  size_t best = n;
  float nearest = std::numeric_limits<float>::max();
  for (size_t j = cursor_; j < n && keys[j] == key; ++j) {
    const glm::vec3 d = prepared_->position[j] - u;
    if (glm::dot(d, d) < nearest) {
      nearest = glm::dot(d, d);
      best = j;
    }
  }
  if (best == n) return 0.0f;
  if (normal == glm::vec3(0.0f) && !prepared_->normal.empty()) normal = prepared_->normal[best];
  ++stats_.radiiFromConversion;
  return prepared_->radius[best];
}

void PointsChunkWriter::push(const glm::dvec3& world, uint64_t key, const glm::vec3& normal,
                             const glm::vec3& color, double value) {
  const glm::dvec3 u = toFrame(world, frame_);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (!(u.x >= 0.0 && u.y >= 0.0 && u.z >= 0.0 && u.x < 1.0 && u.y < 1.0 && u.z < 1.0)) {
    // Last, in chunks of their own (no radius: no density).
    outside_.push_back({key, world, normal, color, 0.0f, values_.density ? nan : value});
    return;
  }
  glm::vec3 n = unitOrZero(normal);
  float radius = preparedMatch(key, world, n);
  if (radius > 0.0f)
    lastRadius_ = radius;
  else
    radius = lastRadius_;
  if (values_.density) {
    const double r = double(radius) * frame_.size;
    value = r > 0.0 ? double(values_.neighbours) / (std::numbers::pi * r * r) : nan;
  }
  buffer_.push_back({key, world, n, color, radius, value});
  while (buffer_.size() - head_ > perChunk_) cutOne();
}

void PointsChunkWriter::finish() {
  while (head_ < buffer_.size()) cutOne();
  closeGatherings(255, 0);
  // Points outside the frame (removed outliers): root cell chunks after all others, so that no
  // chunk of points inside needs a coarser step for them.
  for (size_t first = 0; first < outside_.size(); first += perChunk_) {
    const auto begin = outside_.begin() + ptrdiff_t(first);
    queue({0, 0,
           std::vector<Point>(
               begin, begin + ptrdiff_t(std::min<size_t>(perChunk_, outside_.size() - first))),
           0, {}});
  }
  outside_.clear();
  flush();
}

void PointsChunkWriter::queue(Pending chunk) {
  chunk.sequence = sequence_++;
  pending_.push_back(std::move(chunk));
  if (pending_.size() >= kBatchChunks) flush();
}

void PointsChunkWriter::give(uint8_t level, uint64_t cell, const std::vector<Point>& points,
                             std::vector<uint64_t> from, bool thinOut) {
  if (level == 0) return;
  const uint8_t up = uint8_t(level - 1);
  const uint64_t parent = cell >> 3;
  // The open gatherings contain the cell, so the innermost one is its parent or contains it.
  if (gatherings_.empty() || gatherings_.back().level != up)
    gatherings_.push_back({up, parent, {}, {}, 0});
  Gathering& g = gatherings_.back();
  if (thinOut) {
    for (size_t i = 0; i < points.size(); i += 8) {
      g.points.push_back(points[i]);
      g.points.back().radius *= std::sqrt(8.0f);
    }
  } else {
    g.points.insert(g.points.end(), points.begin(), points.end());
  }
  // (Many chunks of one split finest cell could give more than a chunk holds: halve again.)
  while (g.points.size() > perChunk_) {
    size_t kept = 0;
    for (size_t i = 0; i < g.points.size(); i += 2) {
      g.points[kept] = g.points[i];
      g.points[kept++].radius *= std::sqrt(2.0f);
    }
    g.points.resize(kept);
  }
  g.chunks.insert(g.chunks.end(), from.begin(), from.end());
  ++g.gifts;
}

void PointsChunkWriter::closeGatherings(uint8_t level, uint64_t cell) {
  while (!gatherings_.empty()) {
    if (level != 255 && cellContains(gatherings_.back().level, gatherings_.back().cell, level, cell))
      return;
    Gathering done = std::move(gatherings_.back());
    gatherings_.pop_back();
    if (done.gifts >= 2) {
      Pending subsample{done.level, done.cell, std::move(done.points), 0, std::move(done.chunks)};
      give(done.level, done.cell, subsample.points, {sequence_}, true);
      queue(std::move(subsample));
    } else {
      give(done.level, done.cell, done.points, std::move(done.chunks), false);
    }
  }
}

// Cut the next chunk from the buffer, which holds more than perChunk_ points (or all that are
// left): enough to know whether a cell holds at most perChunk_.
void PointsChunkWriter::cutOne() {
  const uint64_t first = buffer_[head_].key;
  const int finestShift = 3 * (kMaxLevel - finest_);
  const auto begin = buffer_.begin() + ptrdiff_t(head_);
  const auto limit = buffer_.begin() + ptrdiff_t(std::min(buffer_.size(), head_ + perChunk_ + 1));
  const auto endOf = [&](uint64_t bound) {
    return std::partition_point(begin, limit, [&](const Point& p) { return p.key < bound; });
  };
  uint8_t level = finest_;
  uint64_t cell = first >> finestShift;
  auto end = begin;
  if (continues_) {  // the rest of a finest cell split over several chunks
    end = endOf((cell + 1) << finestShift);
  } else {
    for (int l = 0; l <= finest_; ++l) {
      const int shift = 3 * (kMaxLevel - l);
      const uint64_t c = first >> shift;
      if ((c << shift) < floor_) continue;  // would overlap chunks already cut
      end = endOf((c + 1) << shift);
      if (size_t(end - begin) <= perChunk_ || l == finest_) {
        level = uint8_t(l);
        cell = c;
        break;
      }
    }
  }
  if (size_t(end - begin) > perChunk_) end = begin + perChunk_;  // a finest cell, split
  continues_ = level == finest_ && end != buffer_.end() && (end->key >> finestShift) == cell;
  floor_ = (cell + 1) << (3 * (kMaxLevel - level));
  Pending chunk{level, cell, std::vector<Point>(begin, end), 0, {}};
  // Points without a radius: one from the chunk's density.
  const float densityRadius = float(densityPointRadius(level, chunk.points.size()));
  for (Point& p : chunk.points)
    if (!(p.radius > 0.0f)) p.radius = densityRadius;
  head_ += size_t(end - begin);
  if (head_ > perChunk_) {  // drop what was cut, now and then
    buffer_.erase(buffer_.begin(), buffer_.begin() + ptrdiff_t(head_));
    head_ = 0;
  }
  if (!volume_) {
    closeGatherings(level, cell);
    give(level, cell, chunk.points, {sequence_}, true);
  }
  queue(std::move(chunk));
}

void PointsChunkWriter::flush() {
  std::vector<EncodedChunk> encoded(pending_.size());
  tbb::parallel_for(size_t{0}, pending_.size(), [&](size_t c) {
    const Pending& p = pending_[c];
    EncodedChunk& out = encoded[c];
    const std::array<uint32_t, 3> xyz = mortonDecode(p.key);
    const double cellSize = std::ldexp(1.0, -int(p.level));
    const glm::dvec3 cellMin = glm::dvec3(xyz[0], xyz[1], xyz[2]) * cellSize;
    // The finest step (at most the one asked for) at which every offset fits in an int32 and
    // their span along each axis in kMaxPointOffsetSpan (with a step to spare for rounding).
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    for (const Point& point : p.points) {
      const glm::dvec3 d = toFrame(point.world, frame_) - cellMin;
      lo = glm::min(lo, d);
      hi = glm::max(hi, d);
    }
    const double reach = std::max({-lo.x, -lo.y, -lo.z, hi.x, hi.y, hi.z, 0.0});
    const double span = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
    const double limit = double(kMaxPointOffsetSpan) - 2.0;
    int bits = stepBits_;
    while (bits > 0 && (std::ldexp(reach, bits) > limit || std::ldexp(span, bits) > limit)) --bits;
    if (std::ldexp(reach, bits) > limit || std::ldexp(span, bits) > limit)
      throw std::runtime_error(
          "a point lies more than 2^30 frame sizes from the frame: it cannot "
          "be kept");
    out.coarser = bits < stepBits_;
    PointsChunk chunk;
    chunk.stepBits = uint8_t(bits);
    chunk.offsets.resize(p.points.size());
    if (!volume_) chunk.radii.resize(p.points.size());
    // (Points outside the frame have no radius: the largest the code holds.)
    double largest = 0.0;
    if (colors_) chunk.colors.resize(p.points.size());
    if (normals_) chunk.normals.resize(p.points.size());
    for (size_t i = 0; i < p.points.size(); ++i) {
      const Point& point = p.points[i];
      const glm::dvec3 d = toFrame(point.world, frame_) - cellMin;
      for (int a = 0; a < 3; ++a)
        chunk.offsets[i][a] = int32_t(std::llround(std::ldexp(d[a], bits)));
      const std::array<double, 3> stored =
          pointFramePosition(p.level, p.key, chunk.stepBits, chunk.offsets[i]);
      if (!volume_) {
        chunk.radii[i] = encodePointRadius(point.radius > 0.0f ? double(point.radius) : 1.0);
        if (stored[0] >= 0.0 && stored[1] >= 0.0 && stored[2] >= 0.0 && stored[0] < 1.0 &&
            stored[1] < 1.0 && stored[2] < 1.0)
          largest = std::max(largest, decodePointRadius(chunk.radii[i]));
      }
      const glm::dvec3 back = toWorld(glm::dvec3(stored[0], stored[1], stored[2]), frame_);
      if (p.children.empty()) out.maxError = std::max(out.maxError, glm::length(back - point.world));
      if (colors_)
        for (int a = 0; a < 3; ++a)
          chunk.colors[i][a] = uint16_t(
              std::lround(std::clamp(linearToSrgb(point.color[a]), 0.0f, 1.0f) * 65535.0f));
      if (normals_) {
        const glm::vec3 n = unitOrZero(point.normal);
        for (int a = 0; a < 3; ++a) chunk.normals[i][a] = encodeSnorm16(n[a]);
      }
    }
    out.data = encodePointsChunk(chunk);
    if (!values_.name.empty()) {
      const std::vector<uint32_t> order = decodedPointOrder(out.data, chunk);
      std::vector<double> values(order.size());
      for (size_t i = 0; i < order.size(); ++i) values[i] = p.points[order[i]].value;
      out.values = quantizeValues(values_.name, 0, values);  // its points chunk's id: on adding
    }
    out.desc.kind = volume_ ? kVolumePointsKind : kPointsKind;
    out.desc.level = p.level;
    out.desc.key = p.key;
    out.desc.pointCount = p.points.size();
    // The largest radius inside the frame, rounded up to a float: how far the splats reach out of
    // the cell.
    out.desc.geometricError = float(largest);
    if (double(out.desc.geometricError) < largest)
      out.desc.geometricError = std::nextafter(out.desc.geometricError, 2.0f);
    out.desc.codec = Codec::Raw;  // Draco's bytes do not compress further
  });
  for (size_t c = 0; c < encoded.size(); ++c) {
    const EncodedChunk& e = encoded[c];
    const Pending& p = pending_[c];
    const uint32_t id = writer_.addChunk(e.desc, e.data);
    if (idOf_.size() <= p.sequence) idOf_.resize(p.sequence + 1, 0);
    idOf_[p.sequence] = id;
    for (const uint64_t child : p.children) writer_.setParent(idOf_[child], id);
    stats_.bytes += e.data.size();
    if (e.values) {
      PointValues values = *e.values;
      values.pointsChunk = id;
      ChunkDesc desc;
      desc.kind = kValuesKind;
      desc.level = e.desc.level;
      desc.key = e.desc.key;
      desc.pointCount = e.desc.pointCount;
      desc.codec = Codec::Zstd;  // the writer stores it raw where that is smaller
      const std::vector<std::byte> bytes = encodeValuesChunk(values);
      writer_.addChunk(desc, bytes);
      ++stats_.valuesChunks;
      stats_.valuesBytes += bytes.size();
    }
    if (!p.children.empty()) {
      ++stats_.subsampleChunks;
      stats_.subsamplePoints += e.desc.pointCount;
      continue;
    }
    ++stats_.chunks;
    stats_.points += e.desc.pointCount;
    stats_.coarserChunks += e.coarser ? 1 : 0;
    stats_.maxError = std::max(stats_.maxError, e.maxError);
  }
  pending_.clear();
}

KeptPointsStats keepPoints(Writer& writer, const PointCloud& cloud, const FileHeader& header,
                           int stepBits, uint32_t perChunk, const PointSet* prepared,
                           const KeptValues& values, bool volume) {
  const Frame& frame = header.frame;
  const size_t n = cloud.size();
  std::vector<uint64_t> keys(n);
  tbb::parallel_for(size_t{0}, n,
                    [&](size_t i) { keys[i] = keyOfWorld(cloud.positions[i], frame); });
  const std::vector<uint32_t> order = sortedOrder(keys);  // stable: input order within a key
  PointsChunkWriter out(writer, header, stepBits, cloud.hasColors(), cloud.hasNormals(), perChunk,
                        prepared, values, volume);
  const glm::vec3 none(0.0f);
  const size_t extras = cloud.extraCount();
  for (size_t j = 0; j < n; ++j) {
    const uint32_t i = order[j];
    out.push(cloud.positions[i], keys[i], cloud.hasNormals() ? cloud.normals[i] : none,
             cloud.hasColors() ? cloud.colors[i] : none,
             extras > 0 ? cloud.extras[i * extras] : std::numeric_limits<double>::quiet_NaN());
    if ((j + 1) % 65536 == 0) progressAdvance(65536);
  }
  progressAdvance(n % 65536);
  out.finish();
  return out.stats();
}

KeptPointsStats keepPoints(Writer& writer, const RawSpill& raw, SpillDirectory& directory,
                           const FileHeader& header, int stepBits, uint64_t maxLoadedPoints,
                           uint32_t perChunk, const PointSet* prepared, const KeptValues& values) {
  const Frame& frame = header.frame;
  const Distribution distribution(directory, raw, frame, maxLoadedPoints);
  PointsChunkWriter out(writer, header, stepBits, raw.layout().colors, raw.layout().normals,
                        perChunk, prepared, values);
  const glm::vec3 none(0.0f);
  for (const SpillChunk& chunk : distribution.chunks()) {
    const LoadedPoints loaded = distribution.load(chunk);
    const PointCloud& cloud = loaded.cloud;
    std::vector<uint64_t> keys(cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i) keys[i] = keyOfWorld(cloud.positions[i], frame);
    // A load holds the points of each fine cell in input order, and one key lies in one fine
    // cell: the stable sort by key gives (key, input index) order, as in core.
    const std::vector<uint32_t> order = sortedOrder(keys);
    const size_t extras = cloud.extraCount();
    for (const uint32_t i : order)
      out.push(cloud.positions[i], keys[i], cloud.hasNormals() ? cloud.normals[i] : none,
               cloud.hasColors() ? cloud.colors[i] : none,
               extras > 0 ? cloud.extras[i * extras] : std::numeric_limits<double>::quiet_NaN());
    progressAdvance(cloud.size());
  }
  out.finish();
  return out.stats();
}

PointCloud decodeKeptPoints(const Reader& reader, uint32_t id, uint32_t valuesChunk) {
  const Frame& frame = reader.header().frame;
  const ChunkInfo& info = reader.chunks()[id];
  const PointsChunk chunk = decodePointsChunk(reader, id);
  PointCloud points;
  points.positions.resize(chunk.size());
  for (size_t i = 0; i < chunk.size(); ++i) {
    const std::array<double, 3> u =
        pointFramePosition(info.level, info.key, chunk.stepBits, chunk.offsets[i]);
    points.positions[i] = toWorld(glm::dvec3(u[0], u[1], u[2]), frame);
  }
  for (const std::array<uint16_t, 3>& c : chunk.colors)
    points.colors.emplace_back(srgbToLinear(float(c[0]) / 65535.0f),
                               srgbToLinear(float(c[1]) / 65535.0f),
                               srgbToLinear(float(c[2]) / 65535.0f));
  for (const std::array<int16_t, 3>& n : chunk.normals)
    points.normals.emplace_back(decodeSnorm16(n[0]), decodeSnorm16(n[1]), decodeSnorm16(n[2]));
  if (valuesChunk != kNoParent) {
    const PointValues values = decodeValuesChunk(reader, valuesChunk);
    if (values.pointsChunk != id)
      throw FileError(reader.name(), reader.chunk(valuesChunk).offset,
                      "chunk " + std::to_string(valuesChunk) + ": the values of chunk " +
                          std::to_string(values.pointsChunk) + ", not " + std::to_string(id));
    points.extraNames = {values.name};
    points.extras.resize(values.size());
    for (size_t i = 0; i < values.size(); ++i) points.extras[i] = values.value(i);
  }
  return points;
}

std::vector<uint32_t> valuesChunks(const Reader& reader, const std::string& name) {
  std::vector<uint32_t> of(reader.chunks().size(), kNoParent);
  for (const ChunkInfo& c : reader.chunks()) {
    if (c.kind != kValuesKind) continue;
    const PointValues values = decodeValuesChunk(reader, c.id);
    if (values.name != name) continue;
    if (of[values.pointsChunk] != kNoParent)
      throw FileError(reader.name(), c.offset,
                      "chunk " + std::to_string(c.id) + ": a second values chunk '" + name +
                          "' of chunk " + std::to_string(values.pointsChunk));
    of[values.pointsChunk] = c.id;
  }
  return of;
}

std::vector<std::string> keptValueNames(const Reader& reader, uint8_t kind) {
  std::vector<std::string> names;
  for (const ChunkInfo& c : reader.chunks()) {
    if (c.kind != kValuesKind) continue;
    const PointValues values = decodeValuesChunk(reader, c.id);
    if (reader.chunk(values.pointsChunk).kind == kind &&
        std::find(names.begin(), names.end(), values.name) == names.end())
      names.push_back(values.name);
  }
  return names;
}

void forEachKeptPoints(const Reader& reader,
                       const std::function<void(const PointCloud& points)>& f,
                       const std::string& values, uint8_t kind) {
  const std::vector<bool> subsample = subsampleChunks(reader);
  const std::vector<uint32_t> of =
      values.empty() ? std::vector<uint32_t>(reader.chunks().size(), kNoParent)
                     : valuesChunks(reader, values);
  for (const ChunkInfo& info : reader.chunks()) {
    if (info.kind != kind || subsample[info.id]) continue;
    if (!values.empty() && of[info.id] == kNoParent)
      throw FileError(reader.name(), info.offset,
                      "chunk " + std::to_string(info.id) + ": its points have no values '" +
                          values + "'");
    f(decodeKeptPoints(reader, info.id, of[info.id]));
  }
}

std::vector<uint32_t> keptPointsCut(const Reader& reader, uint64_t maxPoints) {
  const auto& chunks = reader.chunks();
  std::vector<std::vector<uint32_t>> children(chunks.size());
  std::vector<uint32_t> roots;
  for (const ChunkInfo& c : chunks) {
    if (c.kind != kPointsKind) continue;
    if (c.parent == kNoParent || c.parent >= chunks.size() || chunks[c.parent].kind != kPointsKind)
      roots.push_back(c.id);
    else
      children[c.parent].push_back(c.id);
  }
  // Coarsest first: a chunk gives way to its children while the points still fit.
  const auto coarser = [&](uint32_t a, uint32_t b) {
    return std::pair(chunks[a].level, a) > std::pair(chunks[b].level, b);
  };
  std::priority_queue<uint32_t, std::vector<uint32_t>, decltype(coarser)> open(coarser);
  std::vector<uint32_t> cut;
  uint64_t total = 0;
  for (uint32_t r : roots) {
    total += chunks[r].pointCount;
    open.push(r);
  }
  std::vector<bool> replaced(chunks.size(), false);
  while (!open.empty()) {
    const uint32_t c = open.top();
    open.pop();
    if (children[c].empty()) continue;
    uint64_t more = 0;
    for (uint32_t k : children[c]) more += chunks[k].pointCount;
    if (total - chunks[c].pointCount + more > maxPoints) continue;
    total = total - chunks[c].pointCount + more;
    replaced[c] = true;
    for (uint32_t k : children[c]) open.push(k);
  }
  // The cut: the chunks reached and not replaced, in file order.
  std::vector<bool> reached(chunks.size(), false);
  std::vector<uint32_t> stack = roots;
  while (!stack.empty()) {
    const uint32_t c = stack.back();
    stack.pop_back();
    reached[c] = true;
    if (replaced[c]) stack.insert(stack.end(), children[c].begin(), children[c].end());
  }
  for (uint32_t id = 0; id < chunks.size(); ++id)
    if (reached[id] && !replaced[id]) cut.push_back(id);
  return cut;
}

KeptPointsInfo keptPointsInfo(const Reader& reader, uint8_t kind) {
  KeptPointsInfo info;
  const std::vector<bool> subsample = subsampleChunks(reader);
  for (const ChunkInfo& c : reader.chunks()) {
    if (c.kind != kind || subsample[c.id]) continue;
    if (info.chunks++ == 0) {
      const PointsChunk first = decodePointsChunk(reader, c.id);
      info.colors = !first.colors.empty();
      info.normals = !first.normals.empty();
    }
    info.points += c.pointCount;
  }
  return info;
}

}  // namespace iso
