// The E57 reader (ASTM E2807-11): the point clouds of a file's data3D, in order, each with its
// pose applied, streamed packet by packet. Layers: e57_pages.h (header, CRC-checked pages),
// e57_xml.h (what the XML says of each scan), e57_section.h (binary sections and packets),
// e57_bitpack.h (the bitpack codec); this file maps prototype fields to positions, colors and
// intensity.
//
// Decisions where the standard leaves a choice:
//   - positions: cartesianX/Y/Z, else sphericalRange/Azimuth/Elevation (x = r cos(el) cos(az),
//     y = r cos(el) sin(az), z = r sin(el)); then the scan's pose, R(q) p + t with q normalized.
//     Points whose invalid state (of the coordinates used) is not 0 are dropped and counted.
//   - colors: colorRed/Green/Blue mapped to [0, 1] by the scan's colorLimits, else by the fields'
//     minimum and maximum, else (floats without them) taken as [0, 1]; read as sRGB. Points with
//     isColorInvalid not 0 get a neutral grey (sRGB 0.5). Colors are kept only when every scan
//     with points has them.
//   - intensity (ReadOptions::keepExtras, when every scan with points has it): the extra
//     "intensity", the value as stored (scaled integers scaled), NaN where isIntensityInvalid.
//   - notes on dropped points and replaced values are added once the last point has been read.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <limits>
#include <optional>
#include <string_view>

#include "iso/check.h"
#include "iso/error.h"
#include "iso/quantize.h"
#include "base/text.h"
#include "pipeline/io/color_table.h"
#include "pipeline/io/e57_pages.h"
#include "pipeline/io/e57_section.h"
#include "pipeline/io/e57_xml.h"
#include "pipeline/io/narrow.h"
#include "pipeline/io/non_finite.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {
namespace {

// Records decoded at a time: the columns of a batch stay in the L2 cache.
constexpr size_t kBatchRecords = 4096;

// What the reader takes from the standard's point fields (E2807 Table 22).
enum Role : uint8_t {
  kCartesianX,
  kCartesianY,
  kCartesianZ,
  kCartesianInvalid,
  kRange,
  kAzimuth,
  kElevation,
  kSphericalInvalid,
  kRed,
  kGreen,
  kBlue,
  kColorInvalid,
  kIntensity,
  kIntensityInvalid,
  kRoleCount
};
constexpr std::array<std::string_view, kRoleCount> kRoleNames = {
    "cartesianX",     "cartesianY",        "cartesianZ",         "cartesianInvalidState",
    "sphericalRange", "sphericalAzimuth",  "sphericalElevation", "sphericalInvalidState",
    "colorRed",       "colorGreen",        "colorBlue",          "isColorInvalid",
    "intensity",      "isIntensityInvalid"};

// How one scan is read.
struct ScanPlan {
  std::string label;
  std::array<int, kRoleCount> fieldOf{};  // the prototype field of each role, -1 when none
  bool isSpherical = false;
  bool hasColors = false;
  bool hasIntensity = false;
  glm::dmat3 rotation{1.0};
  glm::dvec3 translation{0.0};
  std::array<double, 3> colorLow{};    // value mapped to 0
  std::array<double, 3> colorScale{};  // 1 / (high - low)
  E57Section section;                  // when the scan has records
};

bool hasRole(const ScanPlan& plan, Role role) { return plan.fieldOf[role] >= 0; }

bool hasAll(const ScanPlan& plan, Role first) {
  return hasRole(plan, first) && hasRole(plan, Role(first + 1)) && hasRole(plan, Role(first + 2));
}

// The rotation of a pose's quaternion (w, x, y, z), normalized without overflow or underflow.
glm::dmat3 rotationOf(const std::array<double, 4>& q, const std::string& label,
                      const InputStream& in) {
  double largest = 0.0;
  for (double component : q) largest = std::max(largest, std::abs(component));
  if (largest == 0.0)
    throw FileError(in.name(), std::nullopt, label + ": its pose's rotation quaternion is zero");
  const glm::dquat scaled(q[0] / largest, q[1] / largest, q[2] / largest, q[3] / largest);
  return glm::mat3_cast(glm::normalize(scaled));
}

// The range [low, high] that colors of channel c map to [0, 1].
void planColors(const E57Scan& scan, ScanPlan& plan, const InputStream& in) {
  for (int c = 0; c < 3; ++c) {
    const E57Field& field = scan.prototype[size_t(plan.fieldOf[kRed + c])];
    const double low = scan.colorMinimum[c].value_or(field.lowest.value_or(0.0));
    const double high = scan.colorMaximum[c].value_or(field.highest.value_or(1.0));
    if (!(high > low) || !std::isfinite(high - low))
      throw FileError(in.name(), std::nullopt,
                      fmt::format("{}: its {} values have the limits [{}, {}], not an interval",
                                  plan.label, kRoleNames[kRed + c], low, high));
    plan.colorLow[size_t(c)] = low;
    plan.colorScale[size_t(c)] = 1.0 / (high - low);
  }
}

ScanPlan planScan(const E57Scan& scan, size_t index, const InputStream& in) {
  ScanPlan plan;
  plan.label = e57ScanLabel(scan, index);
  const auto fail = [&](const std::string& reason) {
    throw FileError(in.name(), std::nullopt, plan.label + ": " + reason);
  };
  plan.fieldOf.fill(-1);
  for (size_t f = 0; f < scan.prototype.size(); ++f) {
    const auto* role = std::find(kRoleNames.begin(), kRoleNames.end(), scan.prototype[f].name);
    if (role == kRoleNames.end()) continue;
    int& field = plan.fieldOf[size_t(role - kRoleNames.begin())];
    if (field >= 0) fail(fmt::format("its prototype has two '{}' fields", *role));
    field = static_cast<int>(f);
  }
  if (!hasAll(plan, kCartesianX)) {
    if (!hasAll(plan, kRange))
      fail(
          "its prototype has neither cartesianX, cartesianY and cartesianZ nor sphericalRange, "
          "sphericalAzimuth and sphericalElevation");
    plan.isSpherical = true;
  }
  plan.hasColors = hasAll(plan, kRed);
  plan.hasIntensity = hasRole(plan, kIntensity);
  plan.rotation = rotationOf(scan.rotation, plan.label, in);
  plan.translation = {scan.translation[0], scan.translation[1], scan.translation[2]};
  if (plan.hasColors) planColors(scan, plan, in);
  return plan;
}

// Refuse sections that share bytes: each scan's packets are then read once, so reading takes time
// in proportion to the file whatever its scans claim.
void checkSectionsApart(const std::vector<ScanPlan>& plans, const std::vector<E57Scan>& scans,
                        const E57Pages& pages) {
  std::vector<size_t> order;
  for (size_t i = 0; i < scans.size(); ++i)
    if (scans[i].recordCount > 0) order.push_back(i);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return plans[a].section.begin < plans[b].section.begin; });
  for (size_t k = 1; k < order.size(); ++k) {
    const ScanPlan& before = plans[order[k - 1]];
    const ScanPlan& after = plans[order[k]];
    if (after.section.begin < before.section.end)
      pages.stream().failAt(pages.physicalOffset(after.section.begin),
                            fmt::format("the points of {} and {} share bytes of the file",
                                        before.label, after.label));
  }
}

class E57PointReader final : public PointReader {
 public:
  E57PointReader(InputStream in, const ReadOptions& options)
      : in_(std::move(in)), header_(readE57Header(in_)), pages_(in_, header_) {
    scans_ = readE57Scans(pages_, header_);
    for (size_t i = 0; i < scans_.size(); ++i) {
      plans_.push_back(planScan(scans_[i], i, in_));
      if (scans_[i].recordCount > 0)
        plans_.back().section = readE57Section(pages_, scans_[i], plans_.back().label);
    }
    checkSectionsApart(plans_, scans_, pages_);
    // Sections apart, each holding its records at 1 bit or more: at most 8 records per byte.
    uint64_t declared = 0;
    for (const E57Scan& scan : scans_) declared += scan.recordCount;
    info_.path = in_.path();
    info_.format = fmt::format("e57 {}.{} ({} scan{})", header_.versionMajor, header_.versionMinor,
                               scans_.size(), scans_.size() == 1 ? "" : "s");
    info_.declaredPoints = declared;
    info_.hasColors = everyScanWithPointsHas(&ScanPlan::hasColors,
                                             "colors (colorRed, colorGreen, "
                                             "colorBlue)");
    if (options.keepExtras &&
        everyScanWithPointsHas(&ScanPlan::hasIntensity, "intensity (kept as an extra)"))
      info_.extraNames = {"intensity"};
  }

  const PointFileInfo& info() const override { return info_; }
  const ReadStats& stats() const override { return stats_; }

  size_t read(PointCloud& out, size_t maxPoints) override {
    if (out.extraNames != info_.extraNames) {
      ISO_CHECK(out.size() == 0);
      out.extraNames = info_.extraNames;
      out.extras.clear();
    }
    size_t appended = 0;
    while (appended < maxPoints && scanIndex_ < scans_.size()) {
      const E57Scan& scan = scans_[scanIndex_];
      if (recordsDone_ == scan.recordCount) {
        nextScan();
        continue;
      }
      if (!packets_) startScan();
      const uint64_t available = std::min(scan.recordCount - recordsDone_, availableRecords());
      if (available == 0) {
        if (!packets_->readPacket()) failSectionEnds();
        continue;
      }
      const size_t count =
          static_cast<size_t>(std::min<uint64_t>({available, kBatchRecords, maxPoints - appended}));
      appended += decodeRecords(count, out);
      recordsDone_ += count;
    }
    if (scanIndex_ == scans_.size()) addClosingNotes();
    stats_.pointsRead += appended;
    return appended;
  }

 private:
  // Whether every scan that has points has a property; when some but not all do, a note says
  // which does not and that the property is dropped.
  bool everyScanWithPointsHas(bool ScanPlan::*property, std::string_view what) {
    const ScanPlan* lacking = nullptr;
    bool any = false;
    for (size_t i = 0; i < scans_.size(); ++i) {
      if (scans_[i].recordCount == 0) continue;
      if (plans_[i].*property) {
        any = true;
      } else if (lacking == nullptr) {
        lacking = &plans_[i];
      }
    }
    if (any && lacking != nullptr)
      info_.notes.push_back(fmt::format("{} dropped: {} has none", what, lacking->label));
    return any && lacking == nullptr;
  }

  void nextScan() {
    packets_.reset();
    recordsDone_ = 0;
    ++scanIndex_;
  }

  // Open the scan's packets and choose the roles to decode: positions and their invalid state,
  // colors and intensity as the file's output has them.
  void startScan() {
    const ScanPlan& plan = plans_[scanIndex_];
    packets_.emplace(pages_, plan.section, scans_[scanIndex_], plan.label);
    decoded_.fill(false);
    const Role first = plan.isSpherical ? kRange : kCartesianX;
    for (int r = first; r <= first + 3; ++r) decoded_[size_t(r)] = hasRole(plan, Role(r));
    for (int r = kRed; r <= kColorInvalid; ++r)
      decoded_[size_t(r)] = info_.hasColors && hasRole(plan, Role(r));
    for (int r = kIntensity; r <= kIntensityInvalid; ++r)
      decoded_[size_t(r)] = !info_.extraNames.empty() && hasRole(plan, Role(r));
    isFieldDecoded_.assign(scans_[scanIndex_].prototype.size(), false);
    for (size_t r = 0; r < kRoleCount; ++r) {
      if (!decoded_[r]) continue;
      columns_[r].resize(kBatchRecords);
      isFieldDecoded_[size_t(plan.fieldOf[r])] = true;
    }
  }

  // Records whose values all arrived: the fewest whole values of a field that takes bits.
  uint64_t availableRecords() {
    uint64_t available = std::numeric_limits<uint64_t>::max();
    for (const E57ByteStream& stream : packets_->streams())
      if (stream.bitWidth() > 0) available = std::min(available, stream.availableValues());
    return available;
  }

  [[noreturn]] void failSectionEnds() const {
    const ScanPlan& plan = plans_[scanIndex_];
    in_.failAt(
        pages_.physicalOffset(plan.section.end),
        fmt::format("{}: its section ends after {} of {} records", plan.label,
                    withSeparators(recordsDone_), withSeparators(scans_[scanIndex_].recordCount)));
  }

  // Decode `count` records of the current scan into out; returns the points appended.
  size_t decodeRecords(size_t count, PointCloud& out) {
    const ScanPlan& plan = plans_[scanIndex_];
    std::vector<E57ByteStream>& streams = packets_->streams();
    for (size_t r = 0; r < kRoleCount; ++r)
      if (decoded_[r]) streams[size_t(plan.fieldOf[r])].decode(count, columns_[r].data());
    for (size_t f = 0; f < streams.size(); ++f)
      if (!isFieldDecoded_[f]) streams[f].skip(count);
    return appendPoints(plan, count, out);
  }

  // The values of a role for the batch, or nullptr when the scan does not decode it.
  const double* column(Role role) const { return decoded_[role] ? columns_[role].data() : nullptr; }

  // Append the batch's valid records with finite positions, in passes: positions, then the
  // colors and intensities of the records kept. Returns the points appended.
  size_t appendPoints(const ScanPlan& plan, size_t count, PointCloud& out) {
    const size_t begin = out.size();
    out.positions.resize(begin + count);
    const size_t kept = appendPositions(plan, count, out.positions.data() + begin);
    out.positions.resize(begin + kept);
    if (info_.hasColors) {
      out.colors.resize(begin + kept);
      appendColors(plan, kept, out.colors.data() + begin);
    }
    if (!info_.extraNames.empty()) {
      out.extras.resize(begin + kept);
      appendIntensities(kept, out.extras.data() + begin);
    }
    return kept;
  }

  // World positions of the records that are valid and finite; their indices go to kept_.
  size_t appendPositions(const ScanPlan& plan, size_t count, glm::dvec3* out) {
    const Role first = plan.isSpherical ? kRange : kCartesianX;
    const double* a = column(first);
    const double* b = column(Role(first + 1));
    const double* c = column(Role(first + 2));
    const double* invalid = column(Role(first + 3));
    const glm::dmat3 rotation = plan.rotation;
    const glm::dvec3 translation = plan.translation;
    uint32_t* records = kept_.data();
    size_t kept = 0;
    for (size_t i = 0; i < count; ++i) {
      if (invalid != nullptr && invalid[i] != 0.0) {
        ++droppedInvalid_;
        continue;
      }
      glm::dvec3 local{a[i], b[i], c[i]};
      if (plan.isSpherical) {
        const double cosElevation = std::cos(c[i]);
        local = {a[i] * cosElevation * std::cos(b[i]), a[i] * cosElevation * std::sin(b[i]),
                 a[i] * std::sin(c[i])};
      }
      const glm::dvec3 position = rotation * local + translation;
      if (!isFinite(position)) {
        ++stats_.droppedNonFinite;
        continue;
      }
      out[kept] = position;
      records[kept++] = static_cast<uint32_t>(i);
    }
    return kept;
  }

  void appendColors(const ScanPlan& plan, size_t kept, glm::vec3* out) {
    const float* table = srgb16ToLinearTable().data();
    const double* invalid = column(kColorInvalid);
    const uint32_t* records = kept_.data();
    const float grey = srgbToLinear(0.5f);
    // Locals, so that the loop does not reload them after each store.
    const std::array<const double*, 3> values = {column(kRed), column(kGreen), column(kBlue)};
    const std::array<double, 3> low = plan.colorLow;
    const std::array<double, 3> scale = plan.colorScale;
    const auto channel = [&](size_t ch, size_t i) {
      double unit = (values[ch][i] - low[ch]) * scale[ch];
      if (!(unit > 0.0)) unit = 0.0;  // NaN too
      if (unit > 1.0) unit = 1.0;
      // 8-bit codes land on entries v * 257 exactly; other ranges within 1 / 131070.
      return table[static_cast<size_t>(unit * 65535.0 + 0.5)];
    };
    size_t neutral = 0;
    for (size_t k = 0; k < kept; ++k) {
      const size_t i = records[k];
      if (invalid != nullptr && invalid[i] != 0.0) {
        ++neutral;
        out[k] = glm::vec3(grey);
      } else {
        out[k] = {channel(0, i), channel(1, i), channel(2, i)};
      }
    }
    neutralColors_ += neutral;
  }

  void appendIntensities(size_t kept, double* out) {
    const double* intensity = column(kIntensity);
    const double* invalid = column(kIntensityInvalid);
    const uint32_t* records = kept_.data();
    for (size_t k = 0; k < kept; ++k) {
      const size_t i = records[k];
      if (invalid != nullptr && invalid[i] != 0.0) {
        ++invalidIntensities_;
        out[k] = std::numeric_limits<double>::quiet_NaN();
      } else {
        out[k] = intensity[i];
      }
    }
  }

  void addClosingNotes() {
    if (hasClosingNotes_) return;
    hasClosingNotes_ = true;
    if (droppedInvalid_ > 0)
      info_.notes.push_back(
          fmt::format("{} points marked invalid (cartesianInvalidState or "
                      "sphericalInvalidState not 0) dropped",
                      withSeparators(droppedInvalid_)));
    if (neutralColors_ > 0)
      info_.notes.push_back(fmt::format("{} points marked isColorInvalid given a neutral grey",
                                        withSeparators(neutralColors_)));
    if (invalidIntensities_ > 0)
      info_.notes.push_back(fmt::format("{} points marked isIntensityInvalid have intensity NaN",
                                        withSeparators(invalidIntensities_)));
  }

  InputStream in_;
  E57Header header_;
  E57Pages pages_;
  std::vector<E57Scan> scans_;
  std::vector<ScanPlan> plans_;
  PointFileInfo info_;
  ReadStats stats_;
  size_t scanIndex_ = 0;
  uint64_t recordsDone_ = 0;  // of the current scan, dropped ones included
  std::optional<E57PacketReader> packets_;
  std::array<bool, kRoleCount> decoded_{};               // the roles the current scan decodes
  std::vector<bool> isFieldDecoded_;                     // per prototype field of the current scan
  std::array<std::vector<double>, kRoleCount> columns_;  // the batch's values of each role
  std::vector<uint32_t> kept_ = std::vector<uint32_t>(kBatchRecords);  // records appended
  uint64_t droppedInvalid_ = 0;
  uint64_t neutralColors_ = 0;
  uint64_t invalidIntensities_ = 0;
  bool hasClosingNotes_ = false;
};

}  // namespace

std::unique_ptr<PointReader> makeE57Reader(InputStream in, const ReadOptions& options) {
  return std::make_unique<E57PointReader>(std::move(in), options);
}

}  // namespace iso::io
