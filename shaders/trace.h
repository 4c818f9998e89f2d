// The ray tracer of the viewer, one source for the GPU (trace.comp.glsl) and the CPU reference
// tracer (viewer/cpu_tracer.cpp): the same statements run in both (specs/viewer.md, "Tracing").
//
// The includer provides, before including this file:
//   FrameParams P;                       the frame's parameters
//   uint poolWord(uint word);            a word of the page pool (global word index)
//   uvec4 chunkState(uint chunk);        the chunk table entry (ChunkEntry.state)
//   void requestChunk(uint chunk);       a ray needs this chunk (streaming)
//   void useChunk(uint chunk);           a ray went through this chunk (for the LRU)
//   vec3 environmentTexel(uint x, uint y);  linear RGB of the environment map
//   vec3 fusedMultiplyAdd(vec3 a, vec3 b, vec3 c);  a·b + c with one rounding
//   bool floatDistances();               records hold float32 distances (kOptionFloatDistances;
//                                        on the GPU a specialization constant, so no branch runs)
// and the macros ISO_INOUT(T) (GLSL `inout T`, C++ `T&`) and ISO_PRECISE (GLSL `precise`: no
// reassociation; C++ keeps the written order anyway).
//
// All coordinates are frame units: the octree root is the cube [0, 1)^3.
// Float literals carry an `f` so that the C++ build does the same single-precision arithmetic.

// ---- Chunks in the page pool -------------------------------------------------------------

uint blobWord(uint firstPage, uint word) {
  uint page = word >> kPageWordsLog2;
  uint physical = firstPage;
  if (page != 0u) physical = poolWord(firstPage * kPageWords + kBlobPageList + page);
  return poolWord(physical * kPageWords + (word & (kPageWords - 1u)));
}

// Words of a corner record's distances.
uint distanceWords() {
  return floatDistances() ? kRecordFloatDistanceWords : kRecordDistanceWords;
}

// The surface cell (filled leaf, or a coarser node drawn in place of what is below it) or the
// empty cell that contains a grid point.
struct Cell {
  bool filled;
  uint level;
  uvec3 coord;  // cell coordinates at level
  uint page;    // first pool page of the chunk holding the node
  uint record;  // word of the corner record (filled)
};

// Find the cell of grid point g, descending from the octree root through resident chunks. At a
// cut node (children in other chunks) the node's own patch is drawn when the chunk's geometric
// error covers less than P.lod.x pixels at distance `distance`, or when a child chunk is not
// resident (which `request` then asks for).
Cell locate(uvec3 g, float distance, bool request) {
  Cell cell;
  cell.filled = false;
  uint chunk = P.options.z;
  uint page = chunkState(chunk).x;
  uint nodes = blobWord(page, kBlobNodes);
  uint data = blobWord(page, kBlobData);
  uint recordWords = distanceWords();
  if ((P.options.x & kOptionNormals) != 0u) recordWords += kRecordNormalWords;
  if ((P.options.x & (kOptionColors | kOptionOcclusion)) != 0u) recordWords += kRecordColorWords;
  useChunk(chunk);
  uint node = 0u;
  uint level = 0u;
  for (; level < kGridLevels; ++level) {
    uint w0 = blobWord(page, nodes + 2u * node);
    uint w1 = blobWord(page, nodes + 2u * node + 1u);
    uint mask = w0 & 0xFFu;
    if (mask == 0u) {  // a filled leaf
      cell.filled = true;
      cell.record = data + w1 * recordWords;
      break;
    }
    uint shift = kGridLevels - 1u - level;
    uint octant =
        ((g.x >> shift) & 1u) | (((g.y >> shift) & 1u) << 1u) | (((g.z >> shift) & 1u) << 2u);
    if (((mask >> octant) & 1u) == 0u) {  // an empty child
      level += 1u;
      break;
    }
    uint before = uint(bitCount(mask & ((1u << octant) - 1u)));
    if ((w0 & kNodeCut) == 0u) {
      node = w1 + before;
      continue;
    }
    uint ownRecord = data + blobWord(page, w1) * recordWords;
    uint childChunk = blobWord(page, w1 + 1u + 2u * before);
    uint childRoot = blobWord(page, w1 + 2u + 2u * before);
    float error = uintBitsToFloat(chunkState(chunk).z);
    uvec4 child = chunkState(childChunk);
    bool fineEnough = error <= P.lod.x * P.eye.w * distance;
    // (A root index past the child's nodes would only come from a file whose chunks disagree.)
    bool usable = child.x != kNotResident && childRoot < blobWord(child.x, kBlobNodeCount);
    if (fineEnough || !usable) {
      if (!fineEnough && request) requestChunk(childChunk);
      cell.filled = true;
      cell.record = ownRecord;
      break;
    }
    chunk = childChunk;
    page = child.x;
    nodes = blobWord(page, kBlobNodes);
    data = blobWord(page, kBlobData);
    node = childRoot;
    useChunk(chunk);
  }
  cell.level = level;
  cell.coord = g >> (kGridLevels - level);
  cell.page = page;
  return cell;
}

// The 8 corner distances of a surface cell (corner c = x + 2y + 4z: d0 holds 0-3, d1 holds 4-7),
// in units of the cell's size.
struct Corners {
  vec4 d0;
  vec4 d1;
};

// The distance of corners 0-3 of `codes` in cell units: their snorm8 codes (-128 reads as -127,
// as the format says) over 127 times the unit scaled by 2^shift (4 bits each in `shifts`). The
// same arithmetic as the format's decoder up to a power of two: exactly SurfaceModel's values,
// scaled.
vec4 decodeDistances(uint codes, uint shifts) {
  vec4 q = vec4(float(max(int(codes << 24u) >> 24, -127)), float(max(int(codes << 16u) >> 24, -127)),
                float(max(int(codes << 8u) >> 24, -127)), float(max(int(codes) >> 24, -127)));
  vec4 unit = P.surface.x * vec4(float(1u << (shifts & 15u)), float(1u << ((shifts >> 4u) & 15u)),
                                 float(1u << ((shifts >> 8u) & 15u)),
                                 float(1u << ((shifts >> 12u) & 15u)));
  return (q / 127.0f) * unit;
}

Corners loadCorners(uint page, uint record) {
  Corners c;
  if (floatDistances()) {
    c.d0 = vec4(uintBitsToFloat(blobWord(page, record)),
                uintBitsToFloat(blobWord(page, record + 1u)),
                uintBitsToFloat(blobWord(page, record + 2u)),
                uintBitsToFloat(blobWord(page, record + 3u)));
    c.d1 = vec4(uintBitsToFloat(blobWord(page, record + 4u)),
                uintBitsToFloat(blobWord(page, record + 5u)),
                uintBitsToFloat(blobWord(page, record + 6u)),
                uintBitsToFloat(blobWord(page, record + 7u)));
    return c;
  }
  uint shifts = blobWord(page, record + 2u);
  c.d0 = decodeDistances(blobWord(page, record), shifts);
  c.d1 = decodeDistances(blobWord(page, record + 1u), shifts >> 16u);
  return c;
}

// The local coordinates in the cell (lo, size) of the ray's point o + d·t, accurate to a rounding
// of the result rather than of o: the product and the two sums are carried with their exact
// errors (Dekker's TwoProduct by a fused multiply-add, Knuth's TwoSum). Without it a cell much
// smaller than the distance to the ray's origin gets positions off by about 1e-7·|o|, which a
// ray grazing the surface turns into large errors along it, and into hits or misses that
// SurfaceModel (in double) does not see.
vec3 cellCoordinates(vec3 o, vec3 d, float t, vec3 lo, float size) {
  ISO_PRECISE vec3 product = d * t;
  ISO_PRECISE vec3 productError = fusedMultiplyAdd(d, vec3(t), -product);
  ISO_PRECISE vec3 a = o - lo;
  ISO_PRECISE vec3 aPart = a - o;
  ISO_PRECISE vec3 aError = (o - (a - aPart)) + (-lo - aPart);
  ISO_PRECISE vec3 b = a + product;
  ISO_PRECISE vec3 bPart = b - a;
  ISO_PRECISE vec3 bError = (a - (b - bPart)) + (product - bPart);
  ISO_PRECISE vec3 offset = b + ((aError + bError) + productError);
  return clamp(offset / size, vec3(0.0f), vec3(1.0f));
}

// The trilinear interpolation along the segment of a cell from local coordinates ua to ub, as a
// cubic in s in [0, 1]: f(s) = k.x + k.y s + k.z s^2 + k.w s^3. Interpolated along x first (4
// lines), then y (2 quadratics), then z.
vec4 segmentCubic(Corners c, vec3 ua, vec3 ub) {
  vec3 e = ub - ua;
  vec4 lo = vec4(c.d0.x, c.d0.z, c.d1.x, c.d1.z);  // x = 0; (y, z) = 00, 10, 01, 11
  vec4 hi = vec4(c.d0.y, c.d0.w, c.d1.y, c.d1.w);  // x = 1
  vec4 a = mix(lo, hi, ua.x);                      // the 4 lines: a + b s
  vec4 b = (hi - lo) * e.x;
  vec2 da = vec2(a.y, a.w) - vec2(a.x, a.z);  // y = 1 minus y = 0, for z = 0 and z = 1
  vec2 db = vec2(b.y, b.w) - vec2(b.x, b.z);
  vec2 q0 = vec2(a.x, a.z) + da * ua.y;  // the 2 quadratics q0 + q1 s + q2 s^2
  vec2 q1 = vec2(b.x, b.z) + da * e.y + db * ua.y;
  vec2 q2 = db * e.y;
  float r0 = q0.y - q0.x, r1 = q1.y - q1.x, r2 = q2.y - q2.x;
  return vec4(q0.x + r0 * ua.z, q1.x + r1 * ua.z + r0 * e.z, q2.x + r2 * ua.z + r1 * e.z,
              r2 * e.z);
}

float cubicAt(vec4 k, float s) { return ((k.w * s + k.z) * s + k.y) * s + k.x; }

// Whether the sign change from value a to value b is a crossing for a ray on `side`: +1 or -1,
// the crossing must leave that side; 0, either way. Zero counts as positive (as in
// SurfaceModel), so the surface is the boundary of {f < 0}.
bool crossing(float a, float b, float side) {
  bool negativeA = a < 0.0f;
  if (negativeA == (b < 0.0f)) return false;
  return side == 0.0f || (side > 0.0f) != negativeA;
}

// The first crossing of the cubic k on [0, 1] for a ray on `side`. The cubic is split at its
// critical points, where it is monotonic, so a root between two close roots (a grazing ray, a
// thin part) is not skipped. On success, bracket = (sLo, sHi, f(sLo), f(sHi)).
bool firstCrossing(vec4 k, float side, ISO_INOUT(vec4) bracket) {
  float qa = 3.0f * k.w, qb = 2.0f * k.z, qc = k.y;  // the derivative
  float s1 = 1.0f, s2 = 1.0f;
  float disc = qb * qb - 4.0f * qa * qc;
  if (disc >= 0.0f) {
    float q = -0.5f * (qb + (qb >= 0.0f ? sqrt(disc) : -sqrt(disc)));
    float r1 = qa != 0.0f ? q / qa : 1.0f;
    float r2 = q != 0.0f ? qc / q : 1.0f;
    if (!(r1 > 0.0f && r1 < 1.0f)) r1 = 1.0f;
    if (!(r2 > 0.0f && r2 < 1.0f)) r2 = 1.0f;
    s1 = min(r1, r2);
    s2 = max(r1, r2);
  }
  float f0 = k.x, f1 = cubicAt(k, s1), f2 = cubicAt(k, s2), f3 = k.x + k.y + k.z + k.w;
  if (crossing(f0, f1, side)) {
    bracket = vec4(0.0f, s1, f0, f1);
    return true;
  }
  if (crossing(f1, f2, side)) {
    bracket = vec4(s1, s2, f1, f2);
    return true;
  }
  if (crossing(f2, f3, side)) {
    bracket = vec4(s2, 1.0f, f2, f3);
    return true;
  }
  return false;
}

// The root of the cubic in a bracket (sLo, sHi, f(sLo), f(sHi)) whose ends have opposite signs:
// regula falsi with the Illinois rule (superlinear, and it never leaves the bracket).
float refineRoot(vec4 k, vec4 bracket) {
  float sLo = bracket.x, sHi = bracket.y, fLo = bracket.z, fHi = bracket.w;
  int kept = 0;
  for (int i = 0; i < 24 && sHi > sLo; ++i) {
    float m = clamp(sLo + (sHi - sLo) * fLo / (fLo - fHi), sLo, sHi);
    float fm = cubicAt(k, m);
    if ((fm < 0.0f) == (fLo < 0.0f)) {
      if (m == sLo) break;
      sLo = m;
      fLo = fm;
      if (kept == 1) fHi *= 0.5f;
      kept = 1;
    } else {
      if (m == sHi) break;
      sHi = m;
      fHi = fm;
      if (kept == -1) fLo *= 0.5f;
      kept = -1;
    }
  }
  return (fLo - fHi) != 0.0f ? clamp(sLo + (sHi - sLo) * fLo / (fLo - fHi), sLo, sHi) : sLo;
}

// Its gradient (local units).
vec3 trilinearGradient(Corners c, vec3 u) {
  vec4 a = mix(c.d0, c.d1, u.z);
  vec4 dz = c.d1 - c.d0;
  float gx = mix(a.y - a.x, a.w - a.z, u.y);
  float gy = mix(a.z - a.x, a.w - a.y, u.x);
  float gz = mix(mix(dz.x, dz.y, u.x), mix(dz.z, dz.w, u.x), u.y);
  return vec3(gx, gy, gz);
}

// ---- Rays through the octree ---------------------------------------------------------------

struct Hit {
  float t;
  float from;       // the side of the surface the ray came from: +1 (f >= 0, a front face) or -1
  vec3 normal;      // unit, pointing outside (where the signed distance is positive)
  vec3 color;       // linear RGB: the file's colors, or the material's
  float occlusion;  // baked ambient occlusion (1: open)
};

vec3 decodeOctahedral(vec2 e) {
  vec3 n = vec3(e.x, e.y, 1.0f - abs(e.x) - abs(e.y));
  if (n.z < 0.0f) {
    float x = (1.0f - abs(n.y)) * (n.x >= 0.0f ? 1.0f : -1.0f);
    float y = (1.0f - abs(n.x)) * (n.y >= 0.0f ? 1.0f : -1.0f);
    n.x = x;
    n.y = y;
  }
  return normalize(n);
}

vec3 srgbToLinear(vec3 c) {
  vec3 lo = c / 12.92f;
  vec3 hi = pow((c + 0.055f) / 1.055f, vec3(2.4f));
  return vec3(c.x <= 0.04045f ? lo.x : hi.x, c.y <= 0.04045f ? lo.y : hi.y,
              c.z <= 0.04045f ? lo.z : hi.z);
}

// Trilinear weight of corner k at u.
float cornerWeight(uint k, vec3 u) {
  float wx = (k & 1u) != 0u ? u.x : 1.0f - u.x;
  float wy = (k & 2u) != 0u ? u.y : 1.0f - u.y;
  float wz = (k & 4u) != 0u ? u.z : 1.0f - u.z;
  return wx * wy * wz;
}

// Normal and color at local coordinates u of a surface cell.
void surfaceAttributes(Cell cell, Corners c, vec3 u, ISO_INOUT(Hit) hit) {
  uint word = cell.record + distanceWords();
  vec3 n = trilinearGradient(c, u);
  if ((P.options.x & kOptionNormals) != 0u) {
    vec3 sum = vec3(0.0f);
    for (uint k = 0u; k < 8u; k += 2u) {
      vec4 e = unpackSnorm4x8(blobWord(cell.page, word + k / 2u));
      sum += cornerWeight(k, u) * decodeOctahedral(vec2(e.x, e.y));
      sum += cornerWeight(k + 1u, u) * decodeOctahedral(vec2(e.z, e.w));
    }
    if (dot(sum, sum) > 1e-12f) n = sum;
    word += kRecordNormalWords;
  }
  hit.normal = dot(n, n) > 0.0f ? normalize(n) : vec3(0.0f, 0.0f, 1.0f);
  hit.color = vec3(P.albedo.x, P.albedo.y, P.albedo.z);
  hit.occlusion = 1.0f;
  if ((P.options.x & (kOptionColors | kOptionOcclusion)) != 0u) {
    vec3 sum = vec3(0.0f);
    float open = 0.0f;
    for (uint k = 0u; k < 8u; ++k) {
      vec4 rgba = unpackUnorm4x8(blobWord(cell.page, word + k));
      sum += cornerWeight(k, u) * srgbToLinear(vec3(rgba.x, rgba.y, rgba.z));
      open += cornerWeight(k, u) * rgba.w;
    }
    if ((P.options.x & kOptionColors) != 0u) hit.color = sum;
    if ((P.options.x & kOptionOcclusion) != 0u) hit.occlusion = open;
  }
}

// The first crossing of the surface by the ray o + t·d, t in [tMin, tMax]: the first sign change
// of the trilinear along the ray, found exactly in each cell (segmentCubic, firstCrossing), or
// between the exit of one cell and the entry of the next (the seam rule of SurfaceModel).
// `side` is the side the ray starts on (+1 outside, -1 inside) when it leaves a surface: a
// crossing back into that side is the surface it left (self-intersection) and does not count,
// up to the first empty cell, past which the side is no longer known; 0 takes crossings either
// way (camera rays see both sides). `strict` keeps the side rule all along (back faces hidden).
// `distance` is the path length before o (for the level-of-detail rule); `request` lets the ray
// ask for chunks it lacks. Counts one ray in `rays`.
bool intersect(vec3 o, vec3 d, float tMin, float tMax, float side, bool strict, float distance,
               bool request, ISO_INOUT(Hit) hit, ISO_INOUT(uint) rays) {
  rays += 1u;
  vec3 dir = d;
  if (abs(dir.x) < 1e-12f) dir.x = 1e-12f;
  if (abs(dir.y) < 1e-12f) dir.y = 1e-12f;
  if (abs(dir.z) < 1e-12f) dir.z = 1e-12f;
  vec3 inv = vec3(1.0f) / dir;
  // Clip to the root cube.
  vec3 ta = (vec3(0.0f) - o) * inv;
  vec3 tb = (vec3(1.0f) - o) * inv;
  vec3 tNear = min(ta, tb);
  vec3 tFar = max(ta, tb);
  float t = max(tMin, max(tNear.x, max(tNear.y, tNear.z)));
  float tEnd = min(tMax, min(tFar.x, min(tFar.y, tFar.z)));
  if (t > tEnd) return false;
  vec3 p = o + d * t;
  uvec3 g = uvec3(clamp(p * kGridSize, vec3(0.0f), vec3(float(kGridMax))));
  bool havePrevious = false;
  float previous = 0.0f;  // f at the exit of the previous surface cell
  // The traversal only brackets the first crossing; the root and the attributes are computed once
  // after it (in SIMD execution, work inside the loop costs every lane every step).
  bool found = false;
  Cell hitCell;
  float tIn = 0.0f, tOut = 0.0f;  // the hit cell's segment
  vec4 bracket = vec4(0.0f);  // s in [bracket.x, bracket.y] of that segment (equal: at its entry
                              // face), the values at both ends (before and after, at a face)
  for (uint step = 0u; step < kMaxSteps && !found; ++step) {
    Cell cell = locate(g, distance + t, request);
    float size = 1.0f / float(1u << cell.level);
    vec3 lo = vec3(cell.coord) * size;
    vec3 c0 = (lo - o) * inv;
    vec3 c1 = (lo + vec3(size) - o) * inv;
    vec3 cFar = max(c0, c1);
    float tExit = min(cFar.x, min(cFar.y, cFar.z));
    float tStop = min(tExit, tEnd);
    if (!(tStop > t)) {
      // A cell the ray only touches (an edge or a corner, within rounding): nothing in it counts,
      // as in SurfaceModel.
    } else if (cell.filled) {
      Corners c = loadCorners(cell.page, cell.record);
      float least = min(min(min(c.d0.x, c.d0.y), min(c.d0.z, c.d0.w)),
                        min(min(c.d1.x, c.d1.y), min(c.d1.z, c.d1.w)));
      float most = max(max(max(c.d0.x, c.d0.y), max(c.d0.z, c.d0.w)),
                       max(max(c.d1.x, c.d1.y), max(c.d1.z, c.d1.w)));
      float entry, exit;
      if (least >= 0.0f || most < 0.0f) {
        // One sign at every corner, and so everywhere in the cell: no crossing inside it.
        entry = least >= 0.0f ? 1.0f : -1.0f;
        exit = entry;
        if (havePrevious && crossing(previous, entry, side)) {
          found = true;
          bracket = vec4(0.0f, 0.0f, previous, entry);
        }
      } else {
        vec3 ua = cellCoordinates(o, d, t, lo, size);
        vec3 ub = cellCoordinates(o, d, tStop, lo, size);
        vec4 k = segmentCubic(c, ua, ub);
        entry = k.x;
        exit = k.x + k.y + k.z + k.w;
        if (havePrevious && crossing(previous, entry, side)) {
          found = true;  // the sign changed at the face
          bracket = vec4(0.0f, 0.0f, previous, entry);
        } else {
          found = firstCrossing(k, side, bracket);
        }
      }
      if (found) {
        hitCell = cell;
        tIn = t;
        tOut = tStop;
        hit.from = bracket.z < 0.0f ? -1.0f : 1.0f;
      }
      havePrevious = true;
      previous = exit;
    } else {
      havePrevious = false;
      if (!strict) side = 0.0f;
    }
    if (!found) {
      if (tExit >= tEnd) return false;
      // Step into the face neighbour across the exit face: one cell along the exit axis, and on
      // the other axes a point of this cell's face (the rounded point of the ray may lie in a
      // diagonal neighbour behind it, near an edge, from which the ray would step back), so that
      // every step moves forward.
      t = max(t, tExit);
      p = o + d * t;
      uint axis = (cFar.x <= cFar.y && cFar.x <= cFar.z) ? 0u : (cFar.y <= cFar.z ? 1u : 2u);
      uint shift = kGridLevels - cell.level;
      uvec3 first = cell.coord << shift;
      g = clamp(uvec3(clamp(p * kGridSize, vec3(0.0f), vec3(float(kGridMax)))), first,
                first + uvec3((1u << shift) - 1u));
      uint lower = first[axis];
      uint upper = (cell.coord[axis] + 1u) << shift;
      if (dir[axis] > 0.0f) {
        if (upper > kGridMax) return false;
        g[axis] = upper;
      } else {
        if (lower == 0u) return false;
        g[axis] = lower - 1u;
      }
    }
  }
  if (!found) return false;
  // The root in the bracket, once, on the hit cell's cubic.
  float size = 1.0f / float(1u << hitCell.level);
  vec3 lo = vec3(hitCell.coord) * size;
  vec3 ua = cellCoordinates(o, d, tIn, lo, size);
  vec3 ub = cellCoordinates(o, d, tOut, lo, size);
  Corners c = loadCorners(hitCell.page, hitCell.record);
  vec4 k = segmentCubic(c, ua, ub);
  float s = 0.0f;
  if (bracket.y > bracket.x) {
    // The ends again from the cubic just computed (the same arithmetic as in the loop).
    bracket.z = cubicAt(k, bracket.x);
    bracket.w = cubicAt(k, bracket.y);
    s = (bracket.z < 0.0f) == (bracket.w < 0.0f) ? 0.5f * (bracket.x + bracket.y)
                                                  : refineRoot(k, bracket);
  }
  hit.t = tIn + (tOut - tIn) * s;
  surfaceAttributes(hitCell, c, mix(ua, ub, s), hit);
  return true;
}

// ---- Shading --------------------------------------------------------------------------------

uint hashUint(uint x) {
  x ^= x >> 16u;
  x *= 0x7feb352du;
  x ^= x >> 15u;
  x *= 0x846ca68bu;
  x ^= x >> 16u;
  return x;
}

float randomUnit(ISO_INOUT(uint) state) {
  state = hashUint(state + 0x9e3779b9u);
  return float(state >> 8u) * (1.0f / 16777216.0f);
}

vec3 background(vec3 d) {
  vec3 up = vec3(P.worldUp.x, P.worldUp.y, P.worldUp.z);
  float h = dot(d, up);
  if ((P.options.x & kOptionEnvironment) != 0u) {
    // Equirectangular: longitude around `up`, latitude from it; bilinear filtering.
    vec3 a = abs(up.x) < 0.9f ? vec3(1.0f, 0.0f, 0.0f) : vec3(0.0f, 1.0f, 0.0f);
    vec3 e1 = normalize(cross(up, a));
    vec3 e2 = cross(up, e1);
    float phi = atan(dot(d, e2), dot(d, e1));
    float theta = acos(clamp(h, -1.0f, 1.0f));
    float w = float(P.pool.z), hgt = float(P.pool.w);
    float x = (phi * 0.15915494f + 0.5f) * w - 0.5f;
    float y = theta * 0.31830989f * hgt - 0.5f;
    float fx = floor(x), fy = floor(y);
    float ax = x - fx, ay = y - fy;
    uint x0 = uint(int(fx) < 0 ? int(fx) + int(P.pool.z) : int(fx)) % P.pool.z;
    uint x1 = (x0 + 1u) % P.pool.z;
    uint y0 = uint(clamp(int(fy), 0, int(P.pool.w) - 1));
    uint y1 = uint(clamp(int(fy) + 1, 0, int(P.pool.w) - 1));
    vec3 top = mix(environmentTexel(x0, y0), environmentTexel(x1, y0), ax);
    vec3 bottom = mix(environmentTexel(x0, y1), environmentTexel(x1, y1), ax);
    return P.lod.z * mix(top, bottom, ay);
  }
  vec3 top = vec3(P.skyTop.x, P.skyTop.y, P.skyTop.z);
  vec3 bottom = vec3(P.skyBottom.x, P.skyBottom.y, P.skyBottom.z);
  return mix(bottom, top, clamp(0.5f + 0.5f * h, 0.0f, 1.0f));
}

// Phong lighting at p with the shading normal hit.normal (facing the ray) seen from direction
// -d, with shadow rays that leave the surface on the side `from` of the hit.
vec3 shade(vec3 p, vec3 d, Hit hit, float distance, ISO_INOUT(uint) rng, ISO_INOUT(uint) rays) {
  vec3 n = hit.normal;
  vec3 ambient = vec3(P.ambient.x, P.ambient.y, P.ambient.z);
  vec3 color = ambient * hit.occlusion * hit.color;
  vec3 origin = p + n * P.lod.y;
  for (uint i = 0u; i < kMaxLights; ++i) {
    Light light = P.lights[i];
    uint kind = uint(light.position.w);
    uint samples = kind == kLightArea ? max(uint(light.color.w), 1u) : 1u;
    if (kind == kLightNone) samples = 0u;
    vec3 sum = vec3(0.0f);
    for (uint s = 0u; s < samples; ++s) {
      vec3 at = vec3(light.position.x, light.position.y, light.position.z);
      if (kind == kLightArea) {
        // Stratified over a near-square grid of cells, jittered per pixel.
        uint columns = uint(ceil(sqrt(float(samples))));
        uint rows = (samples + columns - 1u) / columns;
        float a = (float(s % columns) + randomUnit(rng)) / float(columns) - 0.5f;
        float b = (float(s / columns) + randomUnit(rng)) / float(rows) - 0.5f;
        at += a * vec3(light.u.x, light.u.y, light.u.z) + b * vec3(light.v.x, light.v.y, light.v.z);
      }
      vec3 l = at - p;
      float lengthL = length(l);
      l = l / lengthL;
      float lambert = dot(n, l);
      bool lit = lambert > 0.0f;
      if (lit && (P.options.x & kOptionShadows) != 0u) {
        Hit blocker;
        lit = !intersect(origin, l, 0.0f, lengthL, hit.from, false, distance, false, blocker, rays);
      }
      if (lit) {
        vec3 r = reflect(-l, n);
        float specular = pow(max(dot(r, -d), 0.0f), P.albedo.w);
        sum += P.material.x * lambert * hit.color + vec3(P.material.y * specular);
      }
    }
    if (samples > 0u)
      color += vec3(light.color.x, light.color.y, light.color.z) * sum / float(samples);
  }
  return color;
}

// A pending ray's side of the surface (-1, 0, +1) and whether it travels inside a transparent
// object, packed into one float of the ray stack.
float packRayState(float side, bool inMedium) { return side + 1.0f + (inMedium ? 4.0f : 0.0f); }

// The color seen along a camera ray, with reflection and refraction rays up to the bounce limit.
// Camera rays see both sides of the surface: a back face (crossed from f < 0) is shaded with the
// flipped normal, tinted (kOptionBackTint) or passed through (kOptionBackHide). Every hit is shaded
// with the normal facing the ray; the rays that leave it keep the side they leave on.
// Pending rays wait on a small stack of vec4s: origin and path length before it, direction and
// bounce count, weight and the ray's state (packRayState).
vec3 radiance(vec3 o, vec3 d, ISO_INOUT(uint) rng, ISO_INOUT(uint) rays) {
  vec4 stackOrigin[kRayStack];
  vec4 stackDirection[kRayStack];
  vec4 stackWeight[kRayStack];
  bool hideBack = (P.options.x & kOptionBackHide) != 0u;
  // The camera ray first.
  vec3 origin = o;
  vec3 direction = d;
  vec3 weight = vec3(1.0f);
  float before = 0.0f;  // path length before origin
  uint depth = 0u;
  float side = hideBack ? 1.0f : 0.0f;
  bool inMedium = false;
  uint count = 0u;
  vec3 color = vec3(0.0f);
  float reflectivity = (P.options.x & kOptionReflections) != 0u ? P.material.z : 0.0f;
  float transparency = (P.options.x & kOptionRefractions) != 0u ? P.material.w : 0.0f;
  float eta = P.medium.x;
  float offset = P.lod.y;
  bool more = true;  // a ray to trace
  while (more) {
    Hit hit;
    bool primary = depth == 0u;
    if (!intersect(origin, direction, 0.0f, 1e30f, side, primary && hideBack, before,
                   primary && (P.options.x & kOptionRequests) != 0u, hit, rays)) {
      color += weight * background(direction);
    } else {
      vec3 p = origin + direction * hit.t;
      vec3 n = hit.from * hit.normal;  // facing the ray
      hit.normal = n;
      float distance = before + hit.t;
      bool bounce = depth < P.options.y;
      if (!inMedium) {
        // Local shading, then the transmitted and the mirror rays.
        if (hit.from < 0.0f && (P.options.x & kOptionBackTint) != 0u)
          hit.color *= vec3(P.backface.x, P.backface.y, P.backface.z);
        color += weight * (1.0f - reflectivity - transparency) *
                 shade(p, direction, hit, distance, rng, rays);
        float mirror = reflectivity;
        if (bounce && transparency > 0.0f) {
          vec3 r = refract(direction, n, 1.0f / eta);
          if (dot(r, r) > 0.0f && count < kRayStack) {
            stackOrigin[count] = vec4(p - n * offset, distance);
            stackDirection[count] = vec4(normalize(r), float(depth + 1u));
            stackWeight[count] = vec4(weight * transparency, packRayState(-hit.from, true));
            count += 1u;
          } else {
            mirror += transparency;
          }
        }
        if (bounce && mirror > 0.0f && count < kRayStack) {
          stackOrigin[count] = vec4(p + n * offset, distance);
          stackDirection[count] = vec4(reflect(direction, n), float(depth + 1u));
          stackWeight[count] = vec4(weight * mirror, packRayState(hit.from, false));
          count += 1u;
        }
      } else if (bounce && count < kRayStack) {
        // Leaving a transparent object: absorption along the way, then out or totally reflected.
        vec3 absorption = vec3(P.medium.y, P.medium.z, P.medium.w);
        vec3 r = refract(direction, n, eta);
        bool leaves = dot(r, r) > 0.0f;
        stackOrigin[count] = vec4(leaves ? p - n * offset : p + n * offset, distance);
        stackDirection[count] =
            vec4(leaves ? normalize(r) : reflect(direction, n), float(depth + 1u));
        stackWeight[count] = vec4(weight * exp(-absorption * hit.t),
                                  leaves ? packRayState(-hit.from, false)
                                         : packRayState(hit.from, true));
        count += 1u;
      }
    }
    more = count > 0u;
    if (more) {
      count -= 1u;
      origin = vec3(stackOrigin[count].x, stackOrigin[count].y, stackOrigin[count].z);
      before = stackOrigin[count].w;
      direction = vec3(stackDirection[count].x, stackDirection[count].y, stackDirection[count].z);
      depth = uint(stackDirection[count].w);
      weight = vec3(stackWeight[count].x, stackWeight[count].y, stackWeight[count].z);
      uint state = uint(stackWeight[count].w + 0.5f);
      side = float(state & 3u) - 1.0f;
      inMedium = state >= 4u;
    }
  }
  return color;
}

float linearToSrgb(float c) {
  c = clamp(c, 0.0f, 1.0f);
  return c <= 0.0031308f ? 12.92f * c : 1.055f * pow(c, 1.0f / 2.4f) - 0.055f;
}

// The packed 8-bit color of pixel (x, y): the mean of P.image.z jittered samples.
uint renderPixel(uint x, uint y, ISO_INOUT(uint) rays) {
  uint samples = max(P.image.z, 1u);
  uint rng = hashUint(x * 1973u + y * 9277u + P.image.w * 26699u);
  vec3 sum = vec3(0.0f);
  vec3 right = vec3(P.right.x, P.right.y, P.right.z);
  vec3 up = vec3(P.up.x, P.up.y, P.up.z);
  vec3 forward = vec3(P.forward.x, P.forward.y, P.forward.z);
  vec3 eye = vec3(P.eye.x, P.eye.y, P.eye.z);
  for (uint s = 0u; s < samples; ++s) {
    float jx = samples > 1u ? randomUnit(rng) : 0.5f;
    float jy = samples > 1u ? randomUnit(rng) : 0.5f;
    float sx = 2.0f * (float(x) + jx) / float(P.image.x) - 1.0f;
    float sy = 1.0f - 2.0f * (float(y) + jy) / float(P.image.y);
    vec3 d = normalize(forward + sx * right + sy * up);
    sum += radiance(eye, d, rng, rays);
  }
  vec3 c = sum / float(samples);
  uint r = uint(linearToSrgb(c.x) * 255.0f + 0.5f);
  uint gc = uint(linearToSrgb(c.y) * 255.0f + 0.5f);
  uint b = uint(linearToSrgb(c.z) * 255.0f + 0.5f);
  if ((P.options.x & kOptionSwapRB) != 0u) {
    uint swap = r;
    r = b;
    b = swap;
  }
  return r | (gc << 8u) | (b << 16u) | (255u << 24u);
}
