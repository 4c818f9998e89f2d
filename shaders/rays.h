// Rays through the octree: the surface attributes at a hit, and the march from cell to cell to
// the first crossing of the zero set. Part of the tracer (trace.h).

struct Hit {
  float t;
  float from;       // the side of the surface the ray came from: +1 (f >= 0, a front face) or -1
  vec3 normal;      // unit, pointing outside (where the signed distance is positive)
  vec3 color;       // linear RGB: the file's colors, or the material's
  float occlusion;  // baked ambient occlusion (1: open)
  vec4 irradiance;  // rgb: the baked irradiance; w: 1 when the hit has it (a surface of a file
                    // with lighting chunks), else 0
};

// An RGB9E5 code's value (iso/lighting.h): three 9-bit mantissas, a 5-bit exponent (bias 15).
vec3 decodeRgb9e5(uint code) {
  float unit = uintBitsToFloat(((code >> 27u) + 103u) << 23u);  // 2^(e - 24), exactly
  return vec3(float(code & 511u), float((code >> 9u) & 511u), float((code >> 18u) & 511u)) * unit;
}

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

// The linear value of an 8-bit sRGB code (FrameParams.srgbToLinear).
float linearOfSrgb(uint code) { return P.srgbToLinear[code >> 2u][code & 3u]; }

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
      vec4 e = unpackSnorm4x8(blobWord(cell.base, word + k / 2u));
      sum += cornerWeight(k, u) * decodeOctahedral(vec2(e.x, e.y));
      sum += cornerWeight(k + 1u, u) * decodeOctahedral(vec2(e.z, e.w));
    }
    if (dot(sum, sum) > 1e-12f) n = sum;
    word += kRecordNormalWords;
  }
  hit.normal = dot(n, n) > 0.0f ? normalize(n) : vec3(0.0f, 0.0f, 1.0f);
  hit.color = vec3(P.albedo.x, P.albedo.y, P.albedo.z);
  hit.occlusion = 1.0f;
  hit.irradiance = vec4(0.0f);
  if ((P.options.x & (kOptionColors | kOptionOcclusion)) != 0u) {
    vec3 sum = vec3(0.0f);
    float open = 0.0f;
    for (uint k = 0u; k < 8u; ++k) {
      uint rgba = blobWord(cell.base, word + k);
      float weight = cornerWeight(k, u);
      sum += weight * vec3(linearOfSrgb(rgba & 0xFFu), linearOfSrgb((rgba >> 8u) & 0xFFu),
                           linearOfSrgb((rgba >> 16u) & 0xFFu));
      open += weight * (float(rgba >> 24u) / 255.0f);
    }
    if ((P.options.x & kOptionColors) != 0u) hit.color = sum;
    if ((P.options.x & kOptionOcclusion) != 0u) hit.occlusion = open;
    word += kRecordColorWords;
  }
  if ((P.options.x & kOptionIrradiance) != 0u) {
    vec3 sum = vec3(0.0f);
    for (uint k = 0u; k < 8u; ++k)
      sum += cornerWeight(k, u) * decodeRgb9e5(blobWord(cell.base, word + k));
    hit.irradiance = vec4(sum, 1.0f);
  }
}

// A ray's walk through the octree: the ray, its segment still to go, the cell-to-cell state of
// the seam rule, and where it restarts its descents (the last ancestors of its node, the root of
// the chunk it is in).
struct Walk {
  vec3 o;
  vec3 d;
  vec3 dir;  // d without zero components
  vec3 inv;  // 1 / dir
  float t;   // where the current cell is entered
  float tEnd;
  float side;
  bool strict;
  bool request;
  float distance;  // path length before o
  uvec3 g;         // a grid point of the current cell
  uint level;
  uint node;
  ChunkView chunk;
  uint words;  // per corner record
  LodRule lod;
  float lodDistance;  // the distance up to which `lod` holds
  bool havePrevious;
  float previous;  // f at the exit of the previous surface cell
  bool found;
  Cell hitCell;
  float tIn;    // the hit cell's segment
  float tOut;
  vec4 bracket;  // s in [bracket.x, bracket.y] of that segment (equal: at its entry face), the
                 // values at both ends (before and after, at a face)
  uint rootLevel;  // the current chunk's root (the walk restarts there while it stays inside)
  uint rootNode;
  uint up1;  // the node's ancestors one, two and three levels up, in its chunk, the first
  uint up2;  // `known` of them (scalars, not an array: see intersect)
  uint up3;
  uint known;
};

// The level-of-detail rule at the walk's distance: the rule of the near end of its distance's
// bucket (the distance with its mantissa cut to 3 bits: steps of at most 12.5 %), a little finer
// than needed inside the bucket, never coarser. The rule depends on the distance alone, not on
// where the ray started. Returns true when the rule changed.
bool updateLod(ISO_INOUT(Walk) w) {
  float at = w.distance + w.t;
  if (at < w.lodDistance) return false;
  uint bucket = floatBitsToUint(max(at, 0.0f)) & 0xFFF00000u;
  float pixel = P.eye.w * uintBitsToFloat(bucket);  // a pixel's width at the bucket's near end
  w.lod = lodRule(pixel, lodPixels() * pixel);
  w.lodDistance = uintBitsToFloat(bucket + 0x00100000u);
  return true;
}

// One level down from the walk's node toward the cell that holds w.g. Returns true when that
// cell is found: `cell.filled` says whether it is a surface cell (a filled leaf, a node drawn in
// place of its children, or a cut node whose chunk is not resident) or an empty child.
bool descend(ISO_INOUT(Walk) w, ISO_INOUT(Cell) cell) {
  uvec2 n = nodeRecord(w.chunk, w.node);
  uint mask = n.x & 0xFFu;
  if (mask == 0u || drawnInstead(w.lod, n.x, w.level)) {
    cell.filled = true;
    return true;
  }
  uint shift = kGridLevels - 1u - w.level;
  uint octant = ((w.g.x >> shift) & 1u) | (((w.g.y >> shift) & 1u) << 1u) |
                (((w.g.z >> shift) & 1u) << 2u);
  if (((mask >> octant) & 1u) == 0u) {  // an empty child
    w.level += 1u;
    cell.filled = false;
    return true;
  }
  uint before = uint(bitCount(mask & ((1u << octant) - 1u)));
  uint parent = w.node;
  if ((n.x & kNodeCut) == 0u) {
    w.node = n.y + before;
  } else {
    uint childChunk = blobWord(w.chunk.base, n.y + 2u * before);
    uint childRoot = blobWord(w.chunk.base, n.y + 2u * before + 1u);
    if (chunkState(childChunk).x == kNotResident) {
      if (w.request) requestChunk(childChunk);
      cell.filled = true;  // the cut node's own patch until the chunk arrives
      return true;
    }
    ChunkView below = chunkView(childChunk);
    // (A root index past the child's nodes would only come from a file whose chunks disagree.)
    if (childRoot >= blobWord(below.base, kBlobNodeCount)) {
      cell.filled = true;
      return true;
    }
    w.chunk = below;
    useChunk(w.chunk.id);
    w.node = childRoot;
    w.rootLevel = w.level + 1u;
    w.rootNode = childRoot;
  }
  w.up3 = w.up2;
  w.up2 = w.up1;
  w.up1 = parent;
  w.known = min(w.known + 1u, 3u);
  w.level += 1u;
  return false;
}

// The cell that holds w.g (found by descend): a crossing in it or at its entry face ends the walk
// (w.found); else the walk steps into the face neighbour across its exit and restarts at the two
// cells' common ancestor when it keeps it, else at the root of its chunk when that chunk holds
// both cells, else at the top. Returns false when the ray
// leaves the cube or its segment first.
bool visit(ISO_INOUT(Walk) w, ISO_INOUT(Cell) cell) {
  cell.level = w.level;
  cell.coord = w.g >> (kGridLevels - w.level);
  cell.base = w.chunk.base;
  cell.record = w.chunk.data + w.node * w.words;
  float size = 1.0f / float(1u << cell.level);
  vec3 lo = vec3(cell.coord) * size;
  vec3 c0 = (lo - w.o) * w.inv;
  vec3 c1 = (lo + vec3(size) - w.o) * w.inv;
  vec3 cFar = max(c0, c1);
  float tExit = min(cFar.x, min(cFar.y, cFar.z));
  float tStop = min(tExit, w.tEnd);
  if (!(tStop > w.t)) {
    // A cell the ray only touches (an edge or a corner, within rounding): nothing in it counts,
    // as in SurfaceModel.
  } else if (cell.filled) {
    Corners c = loadCorners(cell.base, cell.record);
    float least = min(min(min(c.d0.x, c.d0.y), min(c.d0.z, c.d0.w)),
                      min(min(c.d1.x, c.d1.y), min(c.d1.z, c.d1.w)));
    float most = max(max(max(c.d0.x, c.d0.y), max(c.d0.z, c.d0.w)),
                     max(max(c.d1.x, c.d1.y), max(c.d1.z, c.d1.w)));
    float entry, exit;
    if (least >= 0.0f || most < 0.0f) {
      // One sign at every corner, and so everywhere in the cell: no crossing inside it.
      entry = least >= 0.0f ? 1.0f : -1.0f;
      exit = entry;
      if (w.havePrevious && crossing(w.previous, entry, w.side)) {
        w.found = true;
        w.bracket = vec4(0.0f, 0.0f, w.previous, entry);
      }
    } else {
      vec3 ua = cellCoordinates(w.o, w.d, w.t, lo, size);
      vec3 ub = cellCoordinates(w.o, w.d, tStop, lo, size);
      vec4 k = segmentCubic(c, ua, ub);
      entry = k.x;
      exit = k.x + k.y + k.z + k.w;
      if (w.havePrevious && crossing(w.previous, entry, w.side)) {
        w.found = true;  // the sign changed at the face
        w.bracket = vec4(0.0f, 0.0f, w.previous, entry);
      } else {
        w.found = firstCrossing(k, w.side, w.bracket);
      }
    }
    if (w.found) {
      w.hitCell = cell;
      w.tIn = w.t;
      w.tOut = tStop;
      return true;
    }
    w.havePrevious = true;
    w.previous = exit;
  } else {
    w.havePrevious = false;
    if (!w.strict) w.side = 0.0f;
  }
  if (tExit >= w.tEnd) return false;
  // Step into the face neighbour across the exit face: one cell along the exit axis, and on the
  // other axes a point of this cell's face (the rounded point of the ray may lie in a diagonal
  // neighbour behind it, near an edge, from which the ray would step back), so that every step
  // moves forward.
  w.t = max(w.t, tExit);
  vec3 p = w.o + w.d * w.t;
  uint axis = (cFar.x <= cFar.y && cFar.x <= cFar.z) ? 0u : (cFar.y <= cFar.z ? 1u : 2u);
  uint shift = kGridLevels - cell.level;
  uvec3 first = cell.coord << shift;
  uvec3 g = clamp(uvec3(clamp(p * kGridSize, vec3(0.0f), vec3(float(kGridMax)))), first,
                  first + uvec3((1u << shift) - 1u));
  // (Components picked by selects, not by a variable index: that goes through memory on CPUs.)
  bool onX = axis == 0u, onY = axis == 1u;
  uint lower = onX ? first.x : (onY ? first.y : first.z);
  uint upper = lower + (1u << shift);
  uint next;
  if ((onX ? w.dir.x : (onY ? w.dir.y : w.dir.z)) > 0.0f) {
    if (upper > kGridMax) return false;
    next = upper;
  } else {
    if (lower == 0u) return false;
    next = lower - 1u;
  }
  g = uvec3(onX ? next : g.x, onY ? next : g.y, !onX && !onY ? next : g.z);
  w.g = g;
  // The deepest common ancestor of this cell and the next (the cells of a level are the same for
  // two grid points until their highest differing bit): when it is in this chunk, the next cell
  // is below the chunk's root too.
  uint differ = (first.x ^ g.x) | (first.y ^ g.y) | (first.z ^ g.z);
  uint ancestor = kGridLevels - 1u - uint(findMSB(differ));
  uint nodeLevel = cell.filled ? cell.level : cell.level - 1u;  // an empty cell's node: its parent
  uint up = nodeLevel - ancestor;
  // A new level-of-detail rule may draw a node above the ancestor in place of its children: the
  // descent then starts at the top, so that the cell a ray visits depends on its grid point and
  // its distance alone (the same cells wherever the ray started; coneStart relies on it).
  bool newRule = updateLod(w);
  if (!newRule && ancestor >= w.rootLevel && up <= w.known) {
    // The ancestor is the node, or one of the three kept above it.
    uint a1 = w.up1, a2 = w.up2, a3 = w.up3;
    w.node = up == 0u ? w.node : (up == 1u ? a1 : (up == 2u ? a2 : a3));
    w.up1 = up == 0u ? a1 : (up == 1u ? a2 : a3);
    w.up2 = up == 0u ? a2 : a3;
    w.known -= up;
    w.level = ancestor;
  } else {
    if (newRule || ancestor < w.rootLevel) {
      w.chunk = chunkView(P.options.z);
      w.rootLevel = 0u;
      w.rootNode = 0u;
    }
    w.level = w.rootLevel;
    w.node = w.rootNode;
    w.known = 0u;
  }
  return true;
}

// The first crossing of the surface by the ray o + t·d, t in [tMin, tMax]: the first sign change
// of the trilinear along the ray, found exactly in each cell (segmentCubic, firstCrossing), or
// between the exit of one cell and the entry of the next (the seam rule of SurfaceModel).
// `side` is the side the ray starts on (+1 outside, -1 inside) when it leaves a surface: a
// crossing back into that side is the surface it left (self-intersection) and does not count,
// up to the first empty cell, past which the side is no longer known; 0 takes crossings either
// way (camera rays see both sides). `strict` keeps the side rule all along (back faces hidden).
// `distance` is the path length before o (for the level-of-detail rule); `request` lets the ray
// ask for chunks it lacks.
//
// From one cell to the next the walk restarts its descent at their deepest common ancestor (the
// highest bit in which the two cells' grid coordinates differ) when that is the cell's node or
// one of the three ancestors it keeps (Walk.up1-3, in its chunk), else at the root of the chunk it
// is in while the next cell is below it, else at the top chunk; it descends one node record (one
// load) a level. (A stack of the whole path halved lavapipe's speed: arrays indexed per
// invocation go through memory there; specs/viewer.md.) A node is drawn in place of what is below it
// when its error (node records' codes; a cut node's is its chunk's) covers less than P.lod.x
// pixels at the ray's distance and it spans at most kLodNodePixels pixels, or when the chunk
// below it is not resident (which `request` then asks for). The traversal only brackets the first
// crossing; the root and the attributes are computed once after it (in SIMD execution, work
// inside the loop costs every lane every step). Two loop shapes (flatTraversal(), measured in
// specs/viewer.md): a loop of cells, each with its own loop down the tree, or one loop whose
// turns either descend a level or visit a cell.
bool intersect(vec3 o, vec3 d, float tMin, float tMax, float side, bool strict, float distance,
               bool request, ISO_INOUT(Hit) hit) {
  Walk w;
  w.o = o;
  w.d = d;
  w.dir = nonzeroDirection(d);
  w.inv = vec3(1.0f) / w.dir;
  // Clip to the root cube, then to the box of the nodes that are not empty grown by the widest
  // node the ray's level of detail may draw (kLodNodePixels pixels at its farthest distance) and a
  // margin: outside it every cell is empty, so the walk is the same from the first cell in it.
  vec3 ta = (vec3(0.0f) - o) * w.inv;
  vec3 tb = (vec3(1.0f) - o) * w.inv;
  vec3 tNear = min(ta, tb);
  vec3 tFar = max(ta, tb);
  w.t = max(tMin, max(tNear.x, max(tNear.y, tNear.z)));
  w.tEnd = min(tMax, min(tFar.x, min(tFar.y, tFar.z)));
  if (w.t > w.tEnd) return false;
  float grow = (lodPixels() > 0.0f ? kLodNodePixels * P.eye.w * (distance + w.tEnd) : 0.0f) +
               4.0f / kGridSize;
  ta = (vec3(P.contentLo.x, P.contentLo.y, P.contentLo.z) - vec3(grow) - o) * w.inv;
  tb = (vec3(P.contentHi.x, P.contentHi.y, P.contentHi.z) + vec3(grow) - o) * w.inv;
  tNear = min(ta, tb);
  tFar = max(ta, tb);
  w.t = max(w.t, max(tNear.x, max(tNear.y, tNear.z)));
  w.tEnd = min(w.tEnd, min(tFar.x, min(tFar.y, tFar.z)));
  if (w.t > w.tEnd) return false;
  w.g = uvec3(clamp((o + d * w.t) * kGridSize, vec3(0.0f), vec3(float(kGridMax))));
  w.side = side;
  w.strict = strict;
  w.request = request;
  w.distance = distance;
  w.words = recordWords();
  w.lodDistance = -1.0f;
  updateLod(w);
  w.chunk = chunkView(P.options.z);
  useChunk(w.chunk.id);
  w.level = 0u;
  w.node = 0u;
  w.rootLevel = 0u;
  w.rootNode = 0u;
  w.up1 = 0u;
  w.up2 = 0u;
  w.up3 = 0u;
  w.known = 0u;
  w.havePrevious = false;
  w.previous = 0.0f;
  w.found = false;
  w.bracket = vec4(0.0f);
  Cell cell;
  cell.filled = false;
  if (flatTraversal()) {
    bool descending = true;
    uint steps = 0u;
    for (uint turn = 0u; turn < 8u * kMaxSteps && !w.found; ++turn) {
      if (descending && !descend(w, cell)) continue;
      descending = false;
      if (++steps > kMaxSteps || !visit(w, cell)) return false;
      descending = true;
    }
  } else {
    for (uint step = 0u; step < kMaxSteps && !w.found; ++step) {
      while (!descend(w, cell)) {
      }
      if (!visit(w, cell)) return false;
    }
  }
  if (!w.found) return false;
  hit.from = w.bracket.z < 0.0f ? -1.0f : 1.0f;
  // The root in the bracket, once, on the hit cell's cubic.
  float size = 1.0f / float(1u << w.hitCell.level);
  vec3 lo = vec3(w.hitCell.coord) * size;
  vec3 ua = cellCoordinates(o, d, w.tIn, lo, size);
  vec3 ub = cellCoordinates(o, d, w.tOut, lo, size);
  Corners c = loadCorners(w.hitCell.base, w.hitCell.record);
  vec4 k = segmentCubic(c, ua, ub);
  float s = 0.0f;
  vec4 bracket = w.bracket;
  if (bracket.y > bracket.x) {
    // The ends again from the cubic just computed (the same arithmetic as in the loop).
    bracket.z = cubicAt(k, bracket.x);
    bracket.w = cubicAt(k, bracket.y);
    s = (bracket.z < 0.0f) == (bracket.w < 0.0f) ? 0.5f * (bracket.x + bracket.y)
                                                  : refineRoot(k, bracket);
  }
  hit.t = w.tIn + (w.tOut - w.tIn) * s;
  surfaceAttributes(w.hitCell, c, mix(ua, ub, s), hit);
  return true;
}
