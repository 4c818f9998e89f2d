// Opening .iso files for viewing (asset.h).
#include "viewer/asset.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>

#include "iso/error.h"
#include "iso/surface.h"

namespace iso::viewer {

Asset::Asset(Reader r) : reader(std::move(r)), tree(reader.chunks()) {}

std::unique_ptr<Asset> Asset::open(const std::filesystem::path& path) {
  auto a = std::make_unique<Asset>(Reader::open(path));
  const FileHeader& header = a->reader.header();
  if (a->tree.topChunk() == kNoParent)
    throw FileError(a->reader.name(), std::nullopt, "the file holds no surface to view");
  a->blob = blobOptionsOf(a->reader);
  // Bounds from the coarsest chunk's deepest level.
  const SurfaceChunk top = decodeSurfaceChunk(a->reader, a->tree.topChunk());
  const uint8_t last = uint8_t(top.topology.startLevel + top.topology.depth - 1);
  double lo[3] = {1, 1, 1}, hi[3] = {0, 0, 0};
  const Frame& f = header.frame;
  for (const SurfaceNode& n : top.layout.nodes) {
    if (n.level != last && !n.isLeaf()) continue;
    const auto cell = mortonDecode(n.key);
    const double size = std::ldexp(1.0, -int(n.level));
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], cell[k] * size);
      hi[k] = std::max(hi[k], (cell[k] + 1) * size);
    }
    // Where the cell's surface is: Newton steps from its center along the gradient of the
    // trilinear distance, kept inside the cell.
    std::array<double, 8> distance;
    for (int c = 0; c < 8; ++c)
      distance[c] = (n.isLeaf() ? top.leafValues : top.lodValues).distance[n.corners[c]];
    std::array<double, 3> u = {0.5, 0.5, 0.5}, gradient;
    for (int step = 0; step < 3; ++step) {
      const double value = trilinear(distance, u, &gradient);  // gradient: along u
      const double g2 =
          gradient[0] * gradient[0] + gradient[1] * gradient[1] + gradient[2] * gradient[2];
      if (!(g2 > 1e-12)) break;
      for (int k = 0; k < 3; ++k) u[k] = std::clamp(u[k] - value * gradient[k] / g2, 0.0, 1.0);
    }
    SurfaceCell& world = a->cells.emplace_back();
    world.size = size * f.size;
    for (int k = 0; k < 3; ++k) world.center[k] = f.origin[k] + (cell[k] + u[k]) * size * f.size;
  }
  a->contentLo = glm::vec3(float(lo[0]), float(lo[1]), float(lo[2]));
  a->contentHi = glm::vec3(float(hi[0]), float(hi[1]), float(hi[2]));
  for (int k = 0; k < 3; ++k) {
    a->bounds.lo[k] = f.origin[k] + lo[k] * f.size;
    a->bounds.hi[k] = f.origin[k] + hi[k] * f.size;
  }
  a->splats = buildSplatIndex(a->reader);
  // Airborne and terrestrial LiDAR (LAS) has z up; meshes and photogrammetry mostly y.
  const auto meta = nlohmann::json::parse(a->reader.metadata(), nullptr, false);
  if (meta.is_object() && meta.contains("inputs") && meta["inputs"].is_array())
    for (const auto& input : meta["inputs"])
      if (input.is_object() && input.value("format", "").rfind("las", 0) == 0) a->up = {0, 0, 1};
  return a;
}

FrameSetup cpuFrameSetup(const Asset& asset, uint32_t width, uint32_t height,
                         const Environment* environment) {
  FrameSetup setup;
  setup.width = width;
  setup.height = height;
  setup.topChunk = asset.tree.topChunk();
  setup.chunkCount = uint32_t(asset.reader.chunks().size());
  if (asset.splats) {
    setup.splatIndex = asset.splats->chunk;
    setup.splatRadius = asset.splats->typicalRadius;
    setup.chunkCount += 1;
  }
  setup.blob = asset.blob;
  setup.contentLo = asset.contentLo;
  setup.contentHi = asset.contentHi;
  setup.requests = false;
  setup.environmentWidth = environment ? environment->width : 0;
  setup.environmentHeight = environment ? environment->height : 0;
  return setup;
}

}  // namespace iso::viewer
