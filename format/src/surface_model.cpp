// The finest surface of a file and its queries (see surface_model.h).
#include "iso/surface_model.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "iso/error.h"
#include "iso/flat_map.h"
#include "iso/lighting.h"
#include "iso/reader.h"

namespace iso {
namespace {

uint64_t locationalCode(uint8_t level, uint64_t key) { return (uint64_t{1} << (3 * level)) | key; }

double sign(double v) { return v < 0.0 ? -1.0 : 1.0; }

// Sort values[begin, end) of a tiny array in place (insertion sort).
template <size_t N>
void sortRange(std::array<double, N>& values, int begin, int end) {
  for (int i = begin + 1; i < end; ++i)
    for (int j = i; j > begin && values[size_t(j)] < values[size_t(j - 1)]; --j)
      std::swap(values[size_t(j)], values[size_t(j - 1)]);
}

// The cubic g(s) = c[0] + c[1] s + c[2] s² + c[3] s³.
double evalCubic(const std::array<double, 4>& c, double s) {
  return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

// The root of g in [a, b] where g(a) and g(b) have opposite signs (Illinois false position).
double refineRoot(const std::array<double, 4>& c, double a, double b) {
  double ga = evalCubic(c, a), gb = evalCubic(c, b);
  int side = 0;
  for (int i = 0; i < 100 && b - a > 1e-15 * (1.0 + std::abs(a)); ++i) {
    const double m = (a * gb - b * ga) / (gb - ga);
    const double gm = evalCubic(c, m);
    if (gm == 0.0) return m;
    if (sign(gm) == sign(ga)) {
      a = m;
      ga = gm;
      if (side == -1) gb *= 0.5;
      side = -1;
    } else {
      b = m;
      gb = gm;
      if (side == 1) ga *= 0.5;
      side = 1;
    }
  }
  return 0.5 * (a + b);
}

// The first sign change of the cubic in [0, length] (zero counts as positive, as in the viewer's
// tracer: the surface is the boundary of {f < 0}): split at the critical points, where g is
// monotonic.
std::optional<double> firstRoot(const std::array<double, 4>& c, double length) {
  std::array<double, 4> splits{0.0, length, length, length};
  int count = 1;
  const double qa = 3.0 * c[3], qb = 2.0 * c[2], qc = c[1];
  if (std::abs(qa) > 1e-300) {
    const double disc = qb * qb - 4.0 * qa * qc;
    if (disc >= 0.0) {
      const double q = -0.5 * (qb + std::copysign(std::sqrt(disc), qb));
      const double r1 = q / qa, r2 = q != 0.0 ? qc / q : r1;
      for (double r : {std::min(r1, r2), std::max(r1, r2)})
        if (r > 0.0 && r < length) splits[size_t(count++)] = r;
    }
  } else if (std::abs(qb) > 1e-300) {
    const double r = -qc / qb;
    if (r > 0.0 && r < length) splits[size_t(count++)] = r;
  }
  splits[size_t(count)] = length;
  sortRange(splits, 1, count);
  for (int i = 0; i < count; ++i) {
    const double a = splits[size_t(i)], b = splits[size_t(i + 1)];
    const double ga = evalCubic(c, a), gb = evalCubic(c, b);
    if (sign(ga) != sign(gb)) return gb == 0.0 ? b : refineRoot(c, a, b);
  }
  return std::nullopt;
}

}  // namespace

struct SurfaceModel::Traversal {
  Vec3 origin, direction;
  bool hasPrevious = false;  // the previous filled leaf ended where the next one starts
  double previousExitT = 0.0, previousExitValue = 0.0;
  std::optional<RayHit> hit;
};

bool SurfaceModel::Region::contains(const Vec3& p) const {
  for (size_t a = 0; a < 3; ++a)
    if (!(p[a] >= lo[a] && p[a] <= hi[a])) return false;
  return true;
}

bool SurfaceModel::Region::meetsCell(uint8_t level, uint64_t key) const {
  const auto cell = mortonDecode(key);
  const double size = std::ldexp(1.0, -level);
  for (size_t a = 0; a < 3; ++a) {
    const double origin = double(cell[a]) * size;
    if (origin > hi[a] || origin + size < lo[a]) return false;
  }
  return true;
}

SurfaceModel SurfaceModel::load(const Reader& reader, const std::optional<Region>& region,
                                const ChunkSource& source, uint8_t cutLevel) {
  SurfaceModel model;
  model.header_ = reader.header();
  model.region_ = region;
  model.nodes_.push_back({});
  model.nodes_[0].child.fill(kNoNode);
  FlatMap<uint64_t, uint32_t> index(1024);
  index.insert(locationalCode(0, 0), 0);
  const auto ensureNode = [&](uint8_t level, uint64_t key, auto& self) -> uint32_t {
    if (const uint32_t* found = index.find(locationalCode(level, key))) return *found;
    const uint32_t parent = self(uint8_t(level - 1), key >> 3, self);
    const uint32_t id = uint32_t(model.nodes_.size());
    model.nodes_.push_back({});
    model.nodes_.back().child.fill(kNoNode);
    model.nodes_[parent].child[key & 7] = id;
    index.insert(locationalCode(level, key), id);
    return id;
  };
  struct Cut {
    uint32_t chunk, node;
    uint8_t mask, level;
    uint64_t key;
  };
  std::vector<Cut> cuts;
  const std::vector<uint32_t> lighting = lightingByCell(reader);
  const bool lit = std::any_of(lighting.begin(), lighting.end(),
                               [](uint32_t id) { return id != kNoParent; });
  for (const uint32_t id : chunksFor(reader, region, cutLevel)) {
    const ChunkInfo& info = reader.chunk(id);
    std::shared_ptr<const SurfaceChunk> decoded =
        source ? source(info.id)
               : std::make_shared<const SurfaceChunk>(decodeSurfaceChunk(reader, info.id));
    if (lighting[id] != kNoParent && decoded->leafValues.irradiance.empty()) {
      SurfaceChunk copy = *decoded;
      attachLighting(reader, lighting[id], id, copy);
      decoded = std::make_shared<const SurfaceChunk>(std::move(copy));
    }
    const SurfaceChunk& chunk = *decoded;
    // A corner's values appended to the model's the first time one of its leaves is kept:
    // corner c of values v, through remap (the model's number of each of v's corners, or
    // kNoNode). In a file with lighting, a chunk without it lights its corners with 0.
    const auto cornerOf = [&](const CornerValues& v, std::vector<uint32_t>& remap, uint32_t c) {
      if (remap[c] != kNoNode) return remap[c];
      CornerValues& to = model.corners_;
      remap[c] = uint32_t(to.distance.size());
      to.distance.push_back(v.distance[c]);
      if (!v.normal.empty()) to.normal.push_back(v.normal[c]);
      if (!v.color.empty()) to.color.push_back(v.color[c]);
      if (!v.occlusion.empty()) to.occlusion.push_back(v.occlusion[c]);
      if (lit)
        to.irradiance.push_back(v.irradiance.empty() ? std::array<float, 3>{}
                                                     : v.irradiance[c]);
      model.sources_.push_back({id, c, &v == &chunk.lodValues});
      return remap[c];
    };
    std::vector<uint32_t> leafRemap(chunk.leafValues.size(), kNoNode), lodRemap;
    const auto leafOf = [&](const SurfaceNode& node, const CornerValues& values,
                            std::vector<uint32_t>& remap) {
      Leaf leaf{node.key, node.level, {}};
      for (int c = 0; c < kCorners; ++c)
        leaf.corners[size_t(c)] = cornerOf(values, remap, node.corners[size_t(c)]);
      return leaf;
    };
    std::vector<uint32_t> leafOfNode(lit ? chunk.layout.nodes.size() : 0, kNoNode);
    for (size_t nodeIndex = 0; nodeIndex < chunk.layout.nodes.size(); ++nodeIndex) {
      const SurfaceNode& node = chunk.layout.nodes[nodeIndex];
      if (node.level > cutLevel) continue;
      // A node outside the region (and so everything below it) is never reached by a query.
      if (region && !region->meetsCell(node.level, node.key)) continue;
      const uint32_t id = ensureNode(node.level, node.key, ensureNode);
      if (node.level == cutLevel && !node.isLeaf()) {
        // The internal nodes at the cut level become leaves with their level-of-detail corners.
        if (lodRemap.empty()) lodRemap.assign(chunk.lodValues.size(), kNoNode);
        model.nodes_[id].leaf = uint32_t(model.leaves_.size());
        model.leaves_.push_back(leafOf(node, chunk.lodValues, lodRemap));
        continue;
      }
      if (node.isLeaf()) {
        if (model.nodes_[id].leaf != kNoNode)
          throw FileError(
              reader.name(), info.offset,
              "chunk " + std::to_string(info.id) + ": a leaf overlaps another chunk's leaf");
        model.nodes_[id].leaf = uint32_t(model.leaves_.size());
        if (lit) leafOfNode[nodeIndex] = model.nodes_[id].leaf;
        model.leaves_.push_back(leafOf(node, chunk.leafValues, leafRemap));
      } else if (node.firstChild == kNoNode) {
        cuts.push_back({info.id, id, node.childMask, node.level, node.key});
      }
    }
    for (const CornerOverride& o : chunk.irradianceOverrides)
      if (leafOfNode[o.node] != kNoNode) {
        model.lightOverrides_.insert(uint64_t{leafOfNode[o.node]} << 3 | o.corner,
                                     uint32_t(model.overrideValues_.size()));
        model.overrideValues_.push_back(o.value);
      }
  }
  for (const Node& node : model.nodes_)
    if (node.leaf != kNoNode &&
        std::any_of(node.child.begin(), node.child.end(), [](uint32_t c) { return c != kNoNode; }))
      throw FileError(reader.name(), std::nullopt,
                      "a filled leaf also has children in another chunk");
  for (const Cut& cut : cuts)
    for (int o = 0; o < 8; ++o)
      if ((cut.mask >> o & 1) && model.nodes_[cut.node].child[size_t(o)] == kNoNode &&
          (!region || region->meetsCell(uint8_t(cut.level + 1), cut.key << 3 | uint64_t(o))))
        throw FileError(
            reader.name(), reader.chunk(cut.chunk).offset,
            "chunk " + std::to_string(cut.chunk) + ": a node's children are in no chunk");
  return model;
}

std::vector<uint32_t> SurfaceModel::chunksFor(const Reader& reader,
                                              const std::optional<Region>& region,
                                              uint8_t cutLevel) {
  std::vector<uint32_t> ids;
  for (const ChunkInfo& info : reader.chunks())
    if (info.kind == kSurfaceKind && (!region || region->meetsCell(info.level, info.key)) &&
        info.level <= cutLevel)  // deeper chunks: every node below the cut
      ids.push_back(info.id);
  return ids;
}

uint32_t SurfaceModel::findLeaf(const Vec3& p) const {
  std::array<uint32_t, 3> cell{};
  for (int a = 0; a < 3; ++a) {
    if (!(p[size_t(a)] >= 0.0 && p[size_t(a)] < 1.0)) return kNoNode;
    cell[size_t(a)] =
        std::min<uint32_t>(uint32_t(p[size_t(a)] * double(1u << kMaxLevel)), (1u << kMaxLevel) - 1);
  }
  uint32_t node = 0;
  for (int level = 0; level < kMaxLevel; ++level) {
    if (nodes_[node].leaf != kNoNode) return nodes_[node].leaf;
    const int shift = kMaxLevel - 1 - level;
    const int octant = int((cell[0] >> shift) & 1) | int((cell[1] >> shift) & 1) << 1 |
                       int((cell[2] >> shift) & 1) << 2;
    node = nodes_[node].child[size_t(octant)];
    if (node == kNoNode) return kNoNode;
  }
  return nodes_[node].leaf;
}

namespace {

// p in the leaf's local coordinates, clamped into [0, 1]^3.
Vec3 localCoordinates(const SurfaceModel::Leaf& leaf, const Vec3& p) {
  const auto cell = mortonDecode(leaf.key);
  const double scale = std::ldexp(1.0, leaf.level);
  Vec3 u{};
  for (int a = 0; a < 3; ++a)
    u[size_t(a)] = std::clamp(p[size_t(a)] * scale - double(cell[size_t(a)]), 0.0, 1.0);
  return u;
}

}  // namespace

double SurfaceModel::distanceAt(uint32_t leafId, const Vec3& p,
                                std::array<double, 3>* gradient) const {
  const Leaf& leaf = leaves_[leafId];
  const double scale = std::ldexp(1.0, leaf.level);
  const Vec3 u = localCoordinates(leaf, p);
  std::array<double, 8> f{};
  for (int c = 0; c < 8; ++c) f[size_t(c)] = corners_.distance[leaf.corners[size_t(c)]];
  const double value = trilinear(f, u, gradient);
  if (gradient)
    for (double& g : *gradient) g *= scale;
  return value;
}

const std::array<float, 3>& SurfaceModel::irradianceAt(uint32_t leaf, int corner) const {
  if (!overrideValues_.empty())
    if (const uint32_t* o = lightOverrides_.find(uint64_t{leaf} << 3 | uint64_t(corner)))
      return overrideValues_[*o];
  return corners_.irradiance[leaves_[leaf].corners[size_t(corner)]];
}

std::array<double, 8> SurfaceModel::cornerWeights(uint32_t leaf, const Vec3& p) const {
  return trilinearWeights(localCoordinates(leaves_[leaf], p));
}

SurfaceEval SurfaceModel::evaluate(uint32_t leafId, const Vec3& p) const {
  SurfaceEval e;
  e.distance = distanceAt(leafId, p, &e.gradient);
  if (hasNormals() || hasColors()) {
    const Leaf& leaf = leaves_[leafId];
    const std::array<double, 8> w = trilinearWeights(localCoordinates(leaf, p));
    for (int c = 0; c < 8; ++c) {
      const uint32_t corner = leaf.corners[size_t(c)];
      for (int k = 0; k < 3; ++k) {
        if (hasNormals())
          e.normal[size_t(k)] += float(w[size_t(c)]) * corners_.normal[corner][size_t(k)];
        if (hasColors())
          e.color[size_t(k)] += float(w[size_t(c)]) * corners_.color[corner][size_t(k)];
      }
    }
  }
  if (hasIrradiance()) {
    const Leaf& leaf = leaves_[leafId];
    const std::array<double, 8> w = trilinearWeights(localCoordinates(leaf, p));
    for (int c = 0; c < 8; ++c) {
      const std::array<float, 3>& value = irradianceAt(leafId, c);
      for (int k = 0; k < 3; ++k) e.irradiance[size_t(k)] += float(w[size_t(c)]) * value[size_t(k)];
    }
  }
  if (!hasNormals())
    for (int k = 0; k < 3; ++k) e.normal[size_t(k)] = float(e.gradient[size_t(k)]);
  const float length =
      std::sqrt(e.normal[0] * e.normal[0] + e.normal[1] * e.normal[1] + e.normal[2] * e.normal[2]);
  if (length > 0.0f)
    for (float& n : e.normal) n /= length;
  return e;
}

bool SurfaceModel::intersectLeaf(uint32_t leafId, double t0, double t1, Traversal& state) const {
  const Leaf& leaf = leaves_[leafId];
  // Corners all of one sign: the patch (bounded by them) has no zero inside, and its sign at the
  // entry and the exit is theirs; the cubic is not needed.
  int positive = 0, negative = 0;
  for (uint32_t corner : leaf.corners) {
    const float f = corners_.distance[corner];
    positive += f > 0.0f;
    negative += f < 0.0f;
  }
  if (positive == kCorners || negative == kCorners) {
    const double side = positive == kCorners ? 1.0 : -1.0;
    if (state.hasPrevious && std::abs(state.previousExitT - t0) <= 1e-12 * (1.0 + std::abs(t0)) &&
        sign(state.previousExitValue) != sign(side)) {
      state.hit = RayHit{t0, leafId};
      return true;
    }
    state.hasPrevious = true;
    state.previousExitT = t1;
    state.previousExitValue = side;
    return false;
  }
  const auto cell = mortonDecode(leaf.key);
  const double scale = std::ldexp(1.0, leaf.level);
  // Local coordinates along the ray: u(s) = a + b s with s = t - t0.
  std::array<double, 3> a{}, b{};
  for (int k = 0; k < 3; ++k) {
    a[size_t(k)] = (state.origin[size_t(k)] + t0 * state.direction[size_t(k)]) * scale -
                   double(cell[size_t(k)]);
    b[size_t(k)] = state.direction[size_t(k)] * scale;
  }
  std::array<double, 4> g{};  // the trilinear along the ray, a cubic in s
  for (int c = 0; c < 8; ++c) {
    std::array<double, 4> poly{corners_.distance[leaf.corners[size_t(c)]], 0.0, 0.0, 0.0};
    for (int k = 0; k < 3; ++k) {
      const double p0 = ((c >> k) & 1) ? a[size_t(k)] : 1.0 - a[size_t(k)];
      const double p1 = ((c >> k) & 1) ? b[size_t(k)] : -b[size_t(k)];
      for (int d = 3; d >= 0; --d)
        poly[size_t(d)] = poly[size_t(d)] * p0 + (d > 0 ? poly[size_t(d - 1)] * p1 : 0.0);
    }
    for (int d = 0; d < 4; ++d) g[size_t(d)] += poly[size_t(d)];
  }
  const double length = t1 - t0;
  const double entryValue = g[0];
  if (state.hasPrevious && std::abs(state.previousExitT - t0) <= 1e-12 * (1.0 + std::abs(t0)) &&
      sign(state.previousExitValue) != sign(entryValue)) {
    state.hit = RayHit{t0, leafId};
    return true;
  }
  if (std::optional<double> s = firstRoot(g, length)) {
    state.hit = RayHit{t0 + *s, leafId};
    return true;
  }
  state.hasPrevious = true;
  state.previousExitT = t1;
  state.previousExitValue = evalCubic(g, length);
  return false;
}

bool SurfaceModel::intersectNode(uint32_t nodeId, uint8_t level,
                                 const std::array<uint32_t, 3>& cell, double t0, double t1,
                                 Traversal& state) const {
  const Node& node = nodes_[nodeId];
  if (node.leaf != kNoNode) return intersectLeaf(node.leaf, t0, t1, state);
  static const std::array<double, kMaxLevel + 1> kSizes = [] {
    std::array<double, kMaxLevel + 1> sizes{};
    for (int l = 0; l <= kMaxLevel; ++l) sizes[size_t(l)] = std::ldexp(1.0, -l);
    return sizes;
  }();
  const double size = kSizes[level];
  std::array<double, 5> splits{t0, t1, t1, t1, t1};
  int count = 1;
  for (int k = 0; k < 3; ++k) {
    if (state.direction[size_t(k)] == 0.0) continue;
    const double mid = (double(cell[size_t(k)]) + 0.5) * size;
    const double t = (mid - state.origin[size_t(k)]) / state.direction[size_t(k)];
    if (t > t0 && t < t1) splits[size_t(count++)] = t;
  }
  splits[size_t(count)] = t1;
  sortRange(splits, 1, count);
  for (int i = 0; i < count; ++i) {
    const double ta = splits[size_t(i)], tb = splits[size_t(i + 1)];
    if (!(tb > ta)) continue;
    const double tm = 0.5 * (ta + tb);
    int octant = 0;
    std::array<uint32_t, 3> childCell{};
    for (int k = 0; k < 3; ++k) {
      const double mid = (double(cell[size_t(k)]) + 0.5) * size;
      const int upper = state.origin[size_t(k)] + tm * state.direction[size_t(k)] >= mid ? 1 : 0;
      octant |= upper << k;
      childCell[size_t(k)] = 2 * cell[size_t(k)] + uint32_t(upper);
    }
    const uint32_t child = node.child[size_t(octant)];
    if (child == kNoNode) {
      state.hasPrevious = false;  // empty space breaks the chain of leaves
      continue;
    }
    if (intersectNode(child, uint8_t(level + 1), childCell, ta, tb, state)) return true;
  }
  return false;
}

std::optional<RayHit> SurfaceModel::intersect(const Vec3& origin, const Vec3& direction,
                                              double tMin, double tMax) const {
  // Clip the ray to the frame's cube [0, 1]^3.
  double t0 = tMin, t1 = tMax;
  for (int k = 0; k < 3; ++k) {
    if (direction[size_t(k)] == 0.0) {
      if (origin[size_t(k)] < 0.0 || origin[size_t(k)] > 1.0) return std::nullopt;
      continue;
    }
    double ta = (0.0 - origin[size_t(k)]) / direction[size_t(k)],
           tb = (1.0 - origin[size_t(k)]) / direction[size_t(k)];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 < t1)) return std::nullopt;
  Traversal state;
  state.origin = origin;
  state.direction = direction;
  intersectNode(0, 0, {0, 0, 0}, t0, t1, state);
  return state.hit;
}

std::optional<Vec3> SurfaceModel::project(const Vec3& p, bool* escaped) const {
  Vec3 x = p, previous = p;
  double previousValue = 0.0;
  for (int step = 0; step < 64; ++step) {
    if (region_ && !region_->contains(x)) {  // the points between two inside are inside too
      if (escaped) *escaped = true;
      return std::nullopt;
    }
    const uint32_t leaf = findLeaf(x);
    if (leaf == kNoNode) return std::nullopt;
    SurfaceEval e;
    e.distance = distanceAt(leaf, x, &e.gradient);
    if (step > 0 && sign(e.distance) != sign(previousValue))
      return bisectSignChange(previous, x);  // stepped over the zero set, perhaps at a leaf face
    const double g2 = e.gradient[0] * e.gradient[0] + e.gradient[1] * e.gradient[1] +
                      e.gradient[2] * e.gradient[2];
    if (!(g2 > 0.0)) return std::nullopt;
    const double cellSize = std::ldexp(1.0, -leaves_[leaf].level);
    if (std::abs(e.distance) <= 1e-7 * cellSize) return x;
    double scale = e.distance / g2;
    const double stepLength = std::abs(scale) * std::sqrt(g2);
    if (stepLength > 0.5 * cellSize) scale *= 0.5 * cellSize / stepLength;  // stay near the leaf
    previous = x;
    previousValue = e.distance;
    for (int k = 0; k < 3; ++k) x[size_t(k)] -= scale * e.gradient[size_t(k)];
  }
  return std::nullopt;
}

std::optional<Vec3> SurfaceModel::bisectSignChange(Vec3 a, Vec3 b) const {
  // Regula falsi with the Illinois modification on the segment a→b, whose ends have opposite
  // signs: superlinear on a smooth patch, and still bracketing where the sign changes at a jump
  // between leaves (then the bracket shrinks to the jump).
  const auto at = [&](double t) {
    Vec3 x{};
    for (int k = 0; k < 3; ++k) x[size_t(k)] = a[size_t(k)] + t * (b[size_t(k)] - a[size_t(k)]);
    return x;
  };
  const auto valueAt = [&](const Vec3& x, double& cellSize) -> std::optional<double> {
    const uint32_t leaf = findLeaf(x);
    if (leaf == kNoNode) return std::nullopt;
    cellSize = std::ldexp(1.0, -leaves_[leaf].level);
    return distanceAt(leaf, x, nullptr);
  };
  double cellSize = 0.0;
  const std::optional<double> fa0 = valueAt(a, cellSize), fb0 = valueAt(b, cellSize);
  if (!fa0 || !fb0) return std::nullopt;
  double ta = 0.0, tb = 1.0, fa = *fa0, fb = *fb0;
  int side = 0;  // which end was kept last: -1 a, +1 b
  for (int i = 0; i < 200 && tb - ta > 1e-15; ++i) {
    double t = fa != fb ? ta + (tb - ta) * fa / (fa - fb) : 0.5 * (ta + tb);
    if (!(t > ta && t < tb)) t = 0.5 * (ta + tb);
    const Vec3 x = at(t);
    const std::optional<double> f = valueAt(x, cellSize);
    if (!f) return std::nullopt;
    if (std::abs(*f) <= 1e-7 * cellSize) return x;
    if (sign(*f) == sign(fa)) {
      ta = t;
      fa = *f;
      if (side == -1) fb *= 0.5;  // a moved twice: halve b's weight (Illinois)
      side = -1;
    } else {
      tb = t;
      fb = *f;
      if (side == 1) fa *= 0.5;
      side = 1;
    }
  }
  return at(0.5 * (ta + tb));
}

std::vector<ZeroSetSample> SurfaceModel::sampleZeroSet(int linesPerEdge) const {
  std::vector<uint32_t> all(leaves_.size());
  for (uint32_t id = 0; id < all.size(); ++id) all[id] = id;
  return sampleZeroSet(linesPerEdge, all);
}

std::vector<ZeroSetSample> SurfaceModel::sampleZeroSet(int linesPerEdge,
                                                       std::span<const uint32_t> leaves) const {
  std::vector<ZeroSetSample> samples;
  const int m = std::max(1, linesPerEdge);
  for (const uint32_t id : leaves) {
    const Leaf& leaf = leaves_[id];
    const auto cell = mortonDecode(leaf.key);
    const double size = std::ldexp(1.0, -leaf.level);
    for (int axis = 0; axis < 3; ++axis) {
      const int ua = (axis + 1) % 3, ub = (axis + 2) % 3;
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
          Vec3 lo{}, hi{};
          lo[size_t(ua)] = hi[size_t(ua)] = (double(cell[size_t(ua)]) + (i + 0.5) / m) * size;
          lo[size_t(ub)] = hi[size_t(ub)] = (double(cell[size_t(ub)]) + (j + 0.5) / m) * size;
          lo[size_t(axis)] = double(cell[size_t(axis)]) * size;
          hi[size_t(axis)] = lo[size_t(axis)] + size;
          const double f0 = evaluate(id, lo).distance, f1 = evaluate(id, hi).distance;
          if (sign(f0) == sign(f1) || f0 == f1)
            continue;  // linear along the axis: one root at most
          Vec3 x = lo;
          x[size_t(axis)] += size * f0 / (f0 - f1);
          const SurfaceEval e = evaluate(id, x);
          const double gl =
              std::sqrt(e.gradient[0] * e.gradient[0] + e.gradient[1] * e.gradient[1] +
                        e.gradient[2] * e.gradient[2]);
          if (!(gl > 0.0)) continue;
          const double na = std::abs(e.gradient[size_t(axis)]) / gl;
          if (na < std::abs(e.gradient[size_t(ua)]) / gl ||
              na < std::abs(e.gradient[size_t(ub)]) / gl)
            continue;
          samples.push_back({x, (size / m) * (size / m) / na, id});
        }
    }
  }
  return samples;
}

}  // namespace iso
