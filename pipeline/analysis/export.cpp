// Exports of an .iso file's surface (pipeline/analysis/export.h): the mesh of the zero set, leaf by
// leaf.
#include "pipeline/analysis/export.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "iso/flat_map.h"
#include "iso/lighting.h"
#include "iso/reader.h"
#include "pipeline/points/points.h"

namespace iso {
namespace {

// Loops of open edges longer than this are never closed (capSmallHoles): a bound on the walk.
constexpr size_t kCapEdges = 64;

using Point = std::array<int64_t, 3>;  // on the grid of kMaxLevel

Key128 pointKey(const Point& p) { return {uint64_t(p[0]) | uint64_t(p[1]) << 32, uint64_t(p[2])}; }

struct Sample {
  uint32_t id = 0;  // the point's number
  float value = 0;  // the signed distance there (frame units)
};

class Extractor {
 public:
  explicit Extractor(const SurfaceModel& surface)
      : surface_(surface),
        frame_(surface.header().frame),
        samples_(surface.leaves().size() * 6),
        vertexOf_(surface.leaves().size() * 8) {}

  // Cut leaf `id` into tetrahedra; emit: add their triangles to the mesh (else only sample the
  // points they use, so that leaves cut later read the same values there).
  void leaf(uint32_t id, bool emit = true);
  TriangleMesh mesh;
  MeshStats stats;
  std::vector<uint32_t> vertexLeaf;  // the leaf whose tetrahedron made each vertex

 private:
  // The level of the filled leaf holding a frame position, or -1 (empty, outside).
  int levelAt(const glm::dvec3& p) const {
    for (int a = 0; a < 3; ++a)
      if (!(p[a] >= 0.0 && p[a] < 1.0)) return -1;
    const uint32_t leaf = surface_.findLeaf({p.x, p.y, p.z});
    return leaf == kNoNode ? -1 : int(surface_.leaves()[leaf].level);
  }
  // The value at p: the first (coarsest) leaf's patch that asked for it.
  Sample sample(uint32_t leaf, const Point& p) {
    const auto [slot, added] = samples_.insert(pointKey(p), Sample{});
    if (added) {
      const double unit = std::ldexp(1.0, -kMaxLevel);
      slot->id = nextId_++;
      slot->value =
          float(surface_.evaluate(leaf, {p[0] * unit, p[1] * unit, p[2] * unit}).distance);
    }
    return *slot;
  }
  uint32_t vertex(Sample a, Point pa, Sample b, Point pb);
  uint32_t edgeLeaf(const Point& pa, const Point& pb) const;
  void tetrahedron(const std::array<Sample, 4>& s, const std::array<Point, 4>& p);

  const SurfaceModel& surface_;
  Frame frame_;
  FlatMap<Key128, Sample> samples_;
  FlatMap<Key128, uint32_t> vertexOf_;  // by the two samples' numbers
  uint32_t nextId_ = 0;
  uint32_t current_ = kNoNode;  // the leaf being cut
  bool emit_ = true;            // whether its triangles go into the mesh
};

// The zero of g on [0, 1], where g(0) = g0 and g(1) = g1 differ in sign: regula falsi with the
// Illinois rule, from the linear zero.
template <class F>
double bracketedZero(const F& g, double g0, double g1) {
  double lo = 0.0, hi = 1.0, t = g0 / (g0 - g1);
  int kept = 0;  // which end stayed last: -1 low, 1 high
  for (int i = 0; i < 16 && hi - lo > 1e-9; ++i) {
    t = (lo * g1 - hi * g0) / (g1 - g0);
    const double gt = g(t);
    if (gt == 0.0) break;
    if ((gt < 0.0) == (g0 < 0.0)) {
      lo = t;
      g0 = gt;
      if (kept == 1) g1 *= 0.5;
      kept = 1;
    } else {
      hi = t;
      g1 = gt;
      if (kept == -1) g0 *= 0.5;
      kept = -1;
    }
  }
  return t;
}

// A value of exactly 0 counts as a tiny positive one.
float signedValue(float f) { return f == 0.0f ? 1e-30f : f; }

// The leaf whose patch places the vertex of an edge of the current leaf: the current leaf for an
// edge inside it; for one on its boundary, the coarsest leaf around the edge (the lowest key
// among equals), which every leaf sharing the edge finds alike, in any region of the model.
uint32_t Extractor::edgeLeaf(const Point& pa, const Point& pb) const {
  const SurfaceModel::Leaf& leaf = surface_.leaves()[current_];
  const int64_t size = int64_t{1} << (kMaxLevel - leaf.level);
  const auto cell = mortonDecode(leaf.key);
  // The midpoint, in half steps of the finest grid, and the sides of the cell it lies on.
  std::array<int, 3> side{};  // -1 low face, 1 high face, 0 inside
  glm::dvec3 mid;
  for (size_t a = 0; a < 3; ++a) {
    const int64_t m = pa[a] + pb[a], lo = 2 * int64_t(cell[a]) * size;
    side[a] = m == lo ? -1 : m == lo + 2 * size ? 1 : 0;
    mid[int(a)] = double(m) * std::ldexp(1.0, -kMaxLevel - 1);
  }
  if (side == std::array<int, 3>{0, 0, 0}) return current_;
  uint32_t best = current_;
  const double nudge = std::ldexp(1.0, -kMaxLevel - 2);
  for (int across = 1; across < 8; ++across) {  // which boundary sides to step over
    glm::dvec3 p = mid;
    bool valid = true;
    for (int a = 0; a < 3; ++a) {
      if (!(across >> a & 1)) continue;
      valid = valid && side[size_t(a)] != 0;
      p[a] += side[size_t(a)] * nudge;
    }
    if (!valid) continue;
    for (int a = 0; a < 3; ++a)
      if (side[size_t(a)] != 0 && !(across >> a & 1)) p[a] -= side[size_t(a)] * nudge;
    if (!(p.x >= 0.0 && p.x < 1.0 && p.y >= 0.0 && p.y < 1.0 && p.z >= 0.0 && p.z < 1.0)) continue;
    const uint32_t other = surface_.findLeaf({p.x, p.y, p.z});
    if (other == kNoNode) continue;
    const SurfaceModel::Leaf &o = surface_.leaves()[other], &b = surface_.leaves()[best];
    if (o.level < b.level || (o.level == b.level && o.key < b.key)) best = other;
  }
  return best;
}

uint32_t Extractor::vertex(Sample a, Point pa, Sample b, Point pb) {
  if (b.id < a.id) {  // one order for every tetrahedron sharing the edge
    std::swap(a, b);
    std::swap(pa, pb);
  }
  const auto [slot, added] = vertexOf_.insert({a.id, b.id}, uint32_t(mesh.vertices.size()));
  if (added) {
    const double fa = signedValue(a.value), fb = signedValue(b.value);
    const double unit = std::ldexp(1.0, -kMaxLevel);
    const glm::dvec3 from = glm::dvec3(double(pa[0]), double(pa[1]), double(pa[2])) * unit;
    const glm::dvec3 to = glm::dvec3(double(pb[0]), double(pb[1]), double(pb[2])) * unit;
    // The zero of the leaf's patch along the edge, its ends moved to the samples' values (which a
    // coarser leaf may have given, so the ends' signs bracket it): the vertex lies on the zero set
    // the viewer draws, not on a chord of it.
    const uint32_t leaf = edgeLeaf(pa, pb);
    const auto patch = [&](double s) {
      const glm::dvec3 q = from + s * (to - from);
      return surface_.distanceAt(leaf, {q.x, q.y, q.z});
    };
    const double da = patch(0.0), db = patch(1.0);
    const double t = bracketedZero(
        [&](double s) { return patch(s) + (1.0 - s) * (fa - da) + s * (fb - db); }, fa, fb);
    mesh.vertices.push_back(toWorld(from + t * (to - from), frame_));
    vertexLeaf.push_back(current_);
  }
  return *slot;
}

void Extractor::tetrahedron(const std::array<Sample, 4>& s, const std::array<Point, 4>& p) {
  if (!emit_) return;
  ++stats.tetrahedra;
  std::array<int, 4> in{}, out{};
  int ni = 0, no = 0;
  for (int c = 0; c < 4; ++c) (signedValue(s[size_t(c)].value) < 0.0f ? in[ni++] : out[no++]) = c;
  if (ni == 0 || no == 0) return;
  const auto at = [&](int c) {
    return glm::dvec3(double(p[size_t(c)][0]), double(p[size_t(c)][1]), double(p[size_t(c)][2]));
  };
  // Triangles face from the negative side to the positive one: the tetrahedron's linear field
  // grows from any negative corner to any positive one. The facing is decided on the edges'
  // midpoints: a triangle's vertices move along three edges that share no plane, so any
  // crossings inside the edges give it the same facing, also where a 0 puts one on a corner.
  const glm::dvec3 outward = at(out[0]) - at(in[0]);
  using Edge = std::pair<int, int>;
  const auto emit = [&](Edge e0, Edge e1, Edge e2) {
    const auto mid = [&](Edge e) { return 0.5 * (at(e.first) + at(e.second)); };
    if (glm::dot(glm::cross(mid(e1) - mid(e0), mid(e2) - mid(e0)), outward) < 0.0)
      std::swap(e1, e2);
    std::array<uint32_t, 3> t{};
    const std::array<Edge, 3> edges = {e0, e1, e2};
    for (size_t i = 0; i < 3; ++i) {
      const auto [a, b] = edges[i];
      t[i] = vertex(s[size_t(a)], p[size_t(a)], s[size_t(b)], p[size_t(b)]);
    }
    mesh.triangles.push_back(t);
  };
  if (ni == 1 || no == 1) {
    const bool single = ni == 1;
    const int apex = single ? in[0] : out[0];
    const std::array<int, 4>& others = single ? out : in;
    emit({apex, others[0]}, {apex, others[1]}, {apex, others[2]});
  } else {  // two and two: a quad around the tetrahedron
    const Edge a{in[0], out[0]}, b{in[0], out[1]}, c{in[1], out[1]}, d{in[1], out[0]};
    emit(a, b, c);
    emit(a, c, d);
  }
}

// A face point in half-edges from the face's lowest corner: (0..2, 0..2) along its two axes.
using Corner = std::array<int, 2>;
using FaceTriangle = std::array<Corner, 3>;

// The triangles of a leaf's face, to be fanned to the leaf's centre: two along the diagonal from
// the lowest corner when nothing finer touches the face, else a fan from the face's centre over
// its corners and the midpoints of its split edges (e0 along u at v = 0, e1 along v at u = 2, e2
// along u at v = 2, e3 along v at u = 0), where a quarter with a finer leaf across (`fine`, both
// its edges split then) takes that leaf's diagonal, from its lowest corner, instead. So the
// triangles match those of the finer leaves' faces, and the mesh has no cracks.
std::vector<FaceTriangle> faceTriangles(bool e0, bool e1, bool e2, bool e3,
                                        const std::array<bool, 4>& fine) {
  std::vector<FaceTriangle> triangles;
  if (!(e0 || e1 || e2 || e3 || fine[0] || fine[1] || fine[2] || fine[3])) {
    // The diagonal from the lowest corner, as a finer leaf's face across a quarter has it.
    triangles.push_back({Corner{0, 0}, Corner{2, 0}, Corner{2, 2}});
    triangles.push_back({Corner{0, 0}, Corner{2, 2}, Corner{0, 2}});
  } else {
    // A fan from the centre over the corners and the midpoints of split edges; a quarter with
    // a finer leaf across (both its edges split then) takes that leaf's diagonal, from its
    // lowest corner, instead.
    std::vector<Corner> ring = {{0, 0}};
    if (e0) ring.push_back({1, 0});
    ring.push_back({2, 0});
    if (e1) ring.push_back({2, 1});
    ring.push_back({2, 2});
    if (e2) ring.push_back({1, 2});
    ring.push_back({0, 2});
    if (e3) ring.push_back({0, 1});
    const auto quarterOf = [](const Corner& k) { return (k[0] / 2) | (k[1] / 2) << 1; };
    const auto isCorner = [](const Corner& k) { return k[0] != 1 && k[1] != 1; };
    for (size_t i = 0; i < ring.size(); ++i) {
      const Corner& a = ring[i];
      const Corner& b = ring[(i + 1) % ring.size()];
      const bool half = isCorner(a) != isCorner(b);  // a corner and a midpoint
      const Corner& k = isCorner(a) ? a : b;
      if (half && fine[size_t(quarterOf(k))]) continue;  // the quarter's own triangles below
      triangles.push_back({Corner{1, 1}, a, b});
    }
    for (int q = 0; q < 4; ++q) {
      if (!fine[size_t(q)]) continue;
      const Corner k = {(q & 1) * 2, (q >> 1) * 2};
      const Corner alongU = {1, k[1]}, alongV = {k[0], 1};  // the two edge midpoints
      if (k[0] == k[1]) {  // the lowest or highest corner: the diagonal through the centre
        triangles.push_back({Corner{1, 1}, alongU, k});
        triangles.push_back({Corner{1, 1}, k, alongV});
      } else {  // the diagonal between the midpoints
        triangles.push_back({alongU, k, alongV});
        triangles.push_back({alongU, alongV, Corner{1, 1}});
      }
    }
  }
  return triangles;
}

void Extractor::leaf(uint32_t id, bool emit) {
  const SurfaceModel::Leaf& leaf = surface_.leaves()[id];
  current_ = id;
  emit_ = emit;
  stats.leaves += emit;
  const int level = leaf.level;
  const int64_t size = int64_t{1} << (kMaxLevel - level), half = size / 2;
  const auto cell = mortonDecode(leaf.key);
  const Point origin = {int64_t(cell[0]) * size, int64_t(cell[1]) * size, int64_t(cell[2]) * size};
  const double unit = std::ldexp(1.0, -kMaxLevel), nudge = std::ldexp(1.0, -kMaxLevel - 2);
  const auto frameOf = [&](const Point& p) {
    return glm::dvec3(double(p[0]), double(p[1]), double(p[2])) * unit;
  };
  // Which quarters of each face have a finer leaf across them, and which edges touch one (2:1
  // balance: one level finer at most), from the leaves around points a little off them. A leaf
  // no finer than this one that holds such a point holds the whole cell of this one's size
  // there, so one point of that cell answers for the others.
  std::array<std::array<bool, 4>, 6> fineQuarter{};
  std::array<bool, 6> coarseAcross{};  // a leaf no finer than this one across the whole face
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2, side = face % 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
    const auto across = [&](double qu, double qv) {
      glm::dvec3 p = frameOf(origin);
      p[axis] += double(side * size) * unit + (side ? nudge : -nudge);
      p[u] += qu * double(size) * unit;
      p[v] += qv * double(size) * unit;
      return levelAt(p);
    };
    const int centre = across(0.5, 0.5);
    coarseAcross[size_t(face)] = centre >= 0 && centre <= level;
    if (coarseAcross[size_t(face)]) continue;
    for (int q = 0; q < 4; ++q)
      fineQuarter[size_t(face)][size_t(q)] =
          across(q & 1 ? 0.75 : 0.25, q & 2 ? 0.75 : 0.25) > level;
    const auto& f = fineQuarter[size_t(face)];
    stats.splitFaces += emit && (f[0] || f[1] || f[2] || f[3]);
  }
  // splitEdge[a][i][j]: the edge along axis a at offsets i, j of axes (a+1)%3 and (a+2)%3.
  bool splitEdge[3][2][2] = {};
  for (int a = 0; a < 3; ++a)
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        const int b = (a + 1) % 3, c = (a + 2) % 3;
        bool split = false;
        for (int quadrant = 0; quadrant < 4 && !split; ++quadrant) {
          // Off the edge along b and c (this leaf's own side, or across).
          const bool upB = quadrant & 1, upC = quadrant & 2;
          const bool acrossB = upB != (i == 0), acrossC = upC != (j == 0);
          if (!acrossB && !acrossC) continue;  // inside this leaf
          if (acrossB && !acrossC && coarseAcross[size_t(2 * b + i)]) continue;
          if (acrossC && !acrossB && coarseAcross[size_t(2 * c + j)]) continue;
          for (int along = 0; along < 2; ++along) {
            glm::dvec3 p = frameOf(origin);
            p[a] += double((along ? 3 : 1) * size) * unit / 4;
            p[b] += double(i * size) * unit + (upB ? nudge : -nudge);
            p[c] += double(j * size) * unit + (upC ? nudge : -nudge);
            const int found = levelAt(p);
            split = found > level;
            if (found >= 0) break;  // (a leaf no finer holds the other point too)
          }
        }
        splitEdge[a][i][j] = split;
      }
  bool plain = true;
  for (int a = 0; a < 3; ++a)
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) plain = plain && !splitEdge[a][i][j];
  for (const auto& f : fineQuarter) plain = plain && !(f[0] || f[1] || f[2] || f[3]);
  if (plain) {
    // Six tetrahedra around the diagonal from the lowest corner to the highest: each face is cut
    // by the diagonal from its lowest corner, as the faces of the leaves around cut it.
    const auto corner = [&](int bits) {
      return Point{origin[0] + (bits & 1) * size, origin[1] + (bits >> 1 & 1) * size,
                   origin[2] + (bits >> 2 & 1) * size};
    };
    const Sample low = sample(id, corner(0)), high = sample(id, corner(7));
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        if (a == b) continue;
        const int first = 1 << a, second = first | 1 << b;
        const std::array<Point, 4> p = {corner(0), corner(first), corner(second), corner(7)};
        tetrahedron({low, sample(id, p[1]), sample(id, p[2]), high}, p);
      }
    return;
  }
  // The centre, then a tetrahedron to every triangle of every face.
  const Point centre = {origin[0] + half, origin[1] + half, origin[2] + half};
  const Sample centreSample = sample(id, centre);
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2, side = face % 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
    // A face point at (hu, hv) half-edges from its corner.
    const auto facePoint = [&](int hu, int hv) {
      Point p = origin;
      p[size_t(axis)] += side * size;
      p[size_t(u)] += hu * half;
      p[size_t(v)] += hv * half;
      return p;
    };
    // The face's edges: along u at v = 0 (e0) and v = 2 (e2), along v at u = 2 (e1) and u = 0
    // (e3). An edge along u has offsets (v, axis) in splitEdge[u]; one along v (axis, u).
    const std::vector<FaceTriangle> triangles =
        faceTriangles(splitEdge[u][0][side], splitEdge[v][side][1], splitEdge[u][1][side],
                      splitEdge[v][side][0], fineQuarter[size_t(face)]);
    for (const auto& t : triangles) {
      std::array<Point, 4> p = {centre, facePoint(t[0][0], t[0][1]), facePoint(t[1][0], t[1][1]),
                                facePoint(t[2][0], t[2][1])};
      tetrahedron({centreSample, sample(id, p[1]), sample(id, p[2]), sample(id, p[3])}, p);
    }
  }
}

// Whether a lattice cell next to p (frame units; one of the 8 around it, a quarter of a finest
// leaf away) is empty: there the zero set leaves the filled leaves.
bool besideEmptySpace(const SurfaceModel& surface, const glm::dvec3& p, double finestLeaf) {
  for (int corner = 0; corner < 8; ++corner) {
    Vec3 q{};
    for (int a = 0; a < 3; ++a)
      q[size_t(a)] = p[a] + ((corner >> a & 1) ? 0.25 : -0.25) * finestLeaf;
    if (surface.findLeaf(q) == kNoNode) return true;
  }
  return false;
}

// The mesh's open edges, each as its triangle runs it.
std::vector<std::pair<uint32_t, uint32_t>> openDirectedEdges(const TriangleMesh& mesh) {
  FlatMap<Key128, uint32_t> uses(mesh.triangles.size() * 2);
  for (const auto& t : mesh.triangles)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[size_t(e)], b = t[size_t((e + 1) % 3)];
      ++*uses.insert({std::min(a, b), std::max(a, b)}, 0).first;
    }
  std::vector<std::pair<uint32_t, uint32_t>> open;
  for (const auto& t : mesh.triangles)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[size_t(e)], b = t[size_t((e + 1) % 3)];
      if (*uses.find({std::min(a, b), std::max(a, b)}) == 1) open.emplace_back(a, b);
    }
  return open;
}

// Close the mesh's small holes where the file's zero set leaves its filled leaves (a sharp edge's
// fin whose tip runs out of them, or a zero set pinched through a corner whose value is 0): every
// loop of open edges that is simple, runs along empty space all round and is no wider (its box's
// diagonal) than twice the edge of the coarsest leaf it borders is fanned from its centroid: the
// zero set left those leaves through a face or two. Borders of a region's mesh (with leaves beyond
// them), rims of sheets and holes wider than their leaves stay open. Returns the loops closed.
uint64_t capSmallHoles(const SurfaceModel& surface, TriangleMesh& mesh,
                       std::vector<uint32_t>& vertexLeaf) {
  const std::vector<std::pair<uint32_t, uint32_t>> open = openDirectedEdges(mesh);
  if (open.empty()) return 0;
  FlatMap<uint32_t, uint32_t> next(open.size() * 2), outgoing(open.size() * 2);
  for (const auto& [a, b] : open) {
    next.insert(a, b);
    ++*outgoing.insert(a, 0).first;
  }
  int finest = 0;
  for (const auto& leaf : surface.leaves()) finest = std::max(finest, int(leaf.level));
  const Frame& frame = surface.header().frame;
  const glm::dvec3 origin(frame.origin[0], frame.origin[1], frame.origin[2]);
  const double finestEdge = std::ldexp(1.0, -finest);
  FlatMap<uint32_t, uint8_t> seen(open.size() * 2);
  uint64_t capped = 0;
  for (const auto& edge : open) {
    const uint32_t start = edge.first;
    if (seen.find(start)) continue;
    std::vector<uint32_t> loop;
    bool simple = true;
    for (uint32_t v = start;;) {
      seen.insert(v, 1);
      loop.push_back(v);
      const uint32_t* out = outgoing.find(v);
      const uint32_t* w = next.find(v);
      if (!out || *out != 1 || !w || loop.size() > kCapEdges) {
        simple = false;
        break;
      }
      if (*w == start) break;
      if (seen.find(*w)) {
        simple = false;
        break;
      }
      v = *w;
    }
    if (!simple || loop.size() < 3) continue;
    bool alongEmpty = true;
    glm::dvec3 centroid(0.0), lo(1e300), hi(-1e300);
    int coarsest = finest;
    for (size_t i = 0; i < loop.size() && alongEmpty; ++i) {
      const glm::dvec3& p = mesh.vertices[loop[i]];
      const glm::dvec3 mid = (p + mesh.vertices[loop[(i + 1) % loop.size()]]) * 0.5;
      alongEmpty = besideEmptySpace(surface, (mid - origin) / frame.size, finestEdge);
      centroid += p;
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
      coarsest = std::min(coarsest, int(surface.leaves()[vertexLeaf[loop[i]]].level));
    }
    if (!alongEmpty || glm::distance(lo, hi) / frame.size > std::ldexp(2.0, -coarsest)) continue;
    const uint32_t c = uint32_t(mesh.vertices.size());
    mesh.vertices.push_back(centroid / double(loop.size()));
    vertexLeaf.push_back(vertexLeaf[loop[0]]);
    for (size_t i = 0; i < loop.size(); ++i)  // each open edge run the other way
      mesh.triangles.push_back({loop[(i + 1) % loop.size()], loop[i], c});
    ++capped;
  }
  return capped;
}

}  // namespace

std::vector<uint32_t> leavesCoarseFirst(const SurfaceModel& surface) {
  std::vector<uint32_t> order(surface.leaves().size());
  for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return surface.leaves()[a].level < surface.leaves()[b].level;
  });
  return order;
}

TriangleMesh extractMesh(const SurfaceModel& surface, MeshStats* stats,
                         std::vector<uint32_t>* vertexLeaves, const SurfaceModel::Region* within,
                         std::span<const SurfaceModel::Region> without) {
  // Coarse leaves first: a point on the boundary of leaves of several levels takes the coarsest
  // one's value, which the finer ones' corners there only approximate (quantized).
  const std::vector<uint32_t> order = leavesCoarseFirst(surface);
  // Leaf centres are points of the finest grid: leaves of level kMaxLevel have none.
  if (!order.empty() && surface.leaves()[order.back()].level >= kMaxLevel)
    throw std::runtime_error("leaves of level " + std::to_string(kMaxLevel) +
                             " are too fine for the mesh export (at most " +
                             std::to_string(kMaxLevel - 1) + ")");
  Extractor extractor(surface);
  const auto inside = [&](const SurfaceModel::Leaf& leaf) {
    const double size = std::ldexp(1.0, -int(leaf.level));
    const auto cell = mortonDecode(leaf.key);
    const auto in = [&](const SurfaceModel::Region& r) {
      for (size_t a = 0; a < 3; ++a) {
        const double lo = double(cell[a]) * size;
        if (lo < r.lo[a] || lo + size > r.hi[a]) return false;
      }
      return true;
    };
    if (within && !in(*within)) return false;
    return std::none_of(without.begin(), without.end(), in);
  };

  for (uint32_t id : order) extractor.leaf(id, inside(surface.leaves()[id]));
  extractor.stats.cappedHoles = capSmallHoles(surface, extractor.mesh, extractor.vertexLeaf);
  if (stats) *stats = extractor.stats;
  if (vertexLeaves) *vertexLeaves = std::move(extractor.vertexLeaf);
  return std::move(extractor.mesh);
}

std::optional<BakedAppearance> bakedAppearance(const Reader& reader) {
  if (std::none_of(reader.chunks().begin(), reader.chunks().end(),
                   [](const ChunkInfo& c) { return c.kind == kLightingKind; }))
    return std::nullopt;
  BakedAppearance out;
  const nlohmann::json m = nlohmann::json::parse(reader.metadata(), nullptr, false);
  if (m.is_object() && m.contains("lighting") && m["lighting"].is_object()) {
    const nlohmann::json& l = m["lighting"];
    if (l.contains("diffuse") && l["diffuse"].is_number())
      out.diffuse = std::clamp(l["diffuse"].get<float>(), 0.0f, 1.0f);
    if (l.contains("color") && l["color"].is_array() && l["color"].size() == 3)
      for (size_t a = 0; a < 3; ++a)
        if (l["color"][a].is_number()) out.color[a] = std::clamp(l["color"][a].get<float>(), 0.0f, 1.0f);
  }
  return out;
}

MeshAttributes meshAttributes(const SurfaceModel& surface, const TriangleMesh& mesh,
                              std::span<const uint32_t> vertexLeaves,
                              const BakedAppearance* baked) {
  MeshAttributes out;
  const bool lit = baked != nullptr && surface.hasIrradiance();
  if (surface.hasNormals() || surface.hasColors() || lit) {
    out.normals.resize(mesh.vertices.size());
    if (surface.hasColors() || lit) out.colors.resize(mesh.vertices.size());
  }
  if (out.normals.empty()) return out;
  const Frame& frame = surface.header().frame;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, mesh.vertices.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t v = r.begin(); v < r.end(); ++v) {
                        const glm::dvec3 p = toFrame(mesh.vertices[v], frame);
                        const SurfaceEval e = surface.evaluate(vertexLeaves[v], {p.x, p.y, p.z});
                        out.normals[v] = glm::vec3(e.normal[0], e.normal[1], e.normal[2]);
                        if (out.colors.empty()) continue;
                        glm::vec3 c(e.color[0], e.color[1], e.color[2]);
                        if (lit) {
                          if (!surface.hasColors())
                            c = glm::vec3(baked->color[0], baked->color[1], baked->color[2]);
                          c *= baked->diffuse * glm::vec3(e.irradiance[0], e.irradiance[1],
                                                          e.irradiance[2]);
                        }
                        out.colors[v] = c;
                      }
                    });
  if (!surface.hasNormals()) out.normals.clear();  // (evaluated only for the colors)
  return out;
}

void appendMesh(TriangleMesh& to, const TriangleMesh& mesh) {
  const uint32_t base = uint32_t(to.vertices.size());
  to.vertices.insert(to.vertices.end(), mesh.vertices.begin(), mesh.vertices.end());
  for (const auto& t : mesh.triangles)
    to.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

uint64_t openEdges(const TriangleMesh& mesh) { return openDirectedEdges(mesh).size(); }

}  // namespace iso
