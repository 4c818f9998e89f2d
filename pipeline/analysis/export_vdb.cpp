// The OpenVDB export (pipeline/analysis/export.h), alone in its file: OpenVDB's headers are slow to
// compile, and builds without OpenVDB (ISO_WITH_OPENVDB=OFF) take export_vdb_none.cpp instead.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <vector>

#include "iso/atomic_file.h"
#include "iso/error.h"
#include "pipeline/analysis/export.h"

namespace iso {

namespace {

// What openvdb::io::File::write writes (a seekable archive), to a stream whose errors are
// checked: File's own std::ofstream is never checked, and a full disk gave a cut file and success.
class CheckedArchive : public openvdb::io::Archive {
 public:
  void writeTo(std::ostream& out, const openvdb::GridCPtrVec& grids) const {
    Archive::write(out, grids, /*seekable=*/true);
  }
};

void initialize() {
  static std::once_flag initialized;
  std::call_once(initialized, [] { openvdb::initialize(); });
}

// Throw a FileError naming path when OpenVDB's linear transforms cannot take voxels of this size:
// they refuse a voxel volume below 3 times OpenVDB's tolerance (math::ScaleMap).
void requireVdbVoxel(double voxelSize, const std::filesystem::path& path) {
  const double smallestVolume = 3.0 * openvdb::math::Tolerance<double>::value();
  if (voxelSize * voxelSize * voxelSize >= smallestVolume) return;
  char reason[160];
  std::snprintf(reason, sizeof reason,
                "OpenVDB cannot hold the surface's finest voxels, %.3g units wide (its smallest "
                "are %.3g units)",
                voxelSize, std::cbrt(smallestVolume));
  throw FileError(path.string(), std::nullopt, reason);
}

}  // namespace

void requireOpenVdb(const std::string&) {}

std::vector<double> sampleVdb(const std::filesystem::path& path,
                              std::span<const glm::dvec3> world) {
  initialize();
  openvdb::FloatGrid::Ptr grid;
  try {
    openvdb::io::File file(path.string());
    file.open(false);  // read the grids now, not when first used
    const openvdb::GridPtrVecPtr grids = file.getGrids();
    for (const openvdb::GridBase::Ptr& base : *grids) {
      grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
      if (grid) break;
    }
    file.close();
  } catch (const openvdb::Exception& error) {
    throw FileError(path.string(), std::nullopt, std::string("cannot read: ") + error.what());
  }
  if (!grid) throw FileError(path.string(), std::nullopt, "holds no float grid");
  const openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*grid);
  std::vector<double> out;
  out.reserve(world.size());
  for (const glm::dvec3& p : world) out.push_back(sampler.wsSample(openvdb::Vec3d(p.x, p.y, p.z)));
  return out;
}

VdbStats writeVdb(const SurfaceModel& surface, const std::filesystem::path& path,
                  double bandVoxels) {
  initialize();
  VdbStats stats;
  for (const SurfaceModel::Leaf& leaf : surface.leaves())
    stats.level = std::max(stats.level, int(leaf.level));
  const Frame& frame = surface.header().frame;
  const double h = std::ldexp(1.0, -stats.level);  // frame units
  stats.voxelSize = h * frame.size;
  requireVdbVoxel(stats.voxelSize, path);
  const float band = float(bandVoxels * stats.voxelSize);
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(band);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(stats.voxelSize));
  grid->transform().postTranslate(
      openvdb::Vec3d(frame.origin[0], frame.origin[1], frame.origin[2]));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  grid->setName("surface");
  auto accessor = grid->getAccessor();
  const double bandFrame = bandVoxels * h;
  for (uint32_t id : leavesCoarseFirst(surface)) {  // where leaves meet, the coarsest one's value
    const SurfaceModel::Leaf& leaf = surface.leaves()[id];
    const int64_t n = int64_t{1} << (stats.level - leaf.level);
    const auto cell = mortonDecode(leaf.key);
    const std::array<int64_t, 3> origin = {cell[0] * n, cell[1] * n, cell[2] * n};
    // Blocks of the leaf's lattice, halved while their corners' values (which bound the patch
    // inside, a trilinear function) allow a value within the band.
    struct Block {
      std::array<int64_t, 3> lo;
      int64_t size;
    };
    std::vector<Block> blocks = {{origin, n}};
    while (!blocks.empty()) {
      const Block b = blocks.back();
      blocks.pop_back();
      double lo = 1e300, hi = -1e300;
      for (int c = 0; c < 8; ++c) {
        const Vec3 p = {double(b.lo[0] + (c & 1) * b.size) * h,
                        double(b.lo[1] + (c >> 1 & 1) * b.size) * h,
                        double(b.lo[2] + (c >> 2 & 1) * b.size) * h};
        const double f = surface.evaluate(id, p).distance;
        lo = std::min(lo, f);
        hi = std::max(hi, f);
      }
      if (lo > bandFrame || hi < -bandFrame) continue;
      if (b.size > 1) {
        const int64_t half = b.size / 2;
        for (int c = 0; c < 8; ++c)
          blocks.push_back({{b.lo[0] + (c & 1) * half, b.lo[1] + (c >> 1 & 1) * half,
                             b.lo[2] + (c >> 2 & 1) * half},
                            half});
        continue;
      }
      for (int c = 0; c < 8; ++c) {
        const openvdb::Coord ijk(int(b.lo[0] + (c & 1)), int(b.lo[1] + (c >> 1 & 1)),
                                 int(b.lo[2] + (c >> 2 & 1)));
        if (accessor.isValueOn(ijk)) continue;
        const double f =
            surface.evaluate(id, {ijk.x() * h, ijk.y() * h, ijk.z() * h}).distance * frame.size;
        if (std::abs(f) < band) accessor.setValue(ijk, float(f));
      }
    }
  }
  openvdb::tools::signedFloodFill(grid->tree());
  stats.activeVoxels = grid->activeVoxelCount();
  AtomicFile file(path);
  std::ofstream out(file.temporaryPath(), std::ios::binary | std::ios::trunc);
  errno = 0;
  try {
    CheckedArchive().writeTo(out, {grid});
    out.close();
  } catch (const openvdb::Exception& error) {
    throw FileError(path.string(), std::nullopt, std::string("cannot write: ") + error.what());
  }
  if (out.fail())
    throw FileError(
        path.string(), std::nullopt,
        std::string("cannot write: ") + (errno != 0 ? std::strerror(errno) : "the stream failed"));
  file.commit();
  return stats;
}

}  // namespace iso
