// Rays through the octree: the surface attributes at a hit, and the march from cell to cell to
// the first crossing of the zero set. Part of the tracer (trace.h).

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
  if ((P.options.x & (kOptionColors | kOptionOcclusion)) != 0u) {
    vec3 sum = vec3(0.0f);
    float open = 0.0f;
    for (uint k = 0u; k < 8u; ++k) {
      vec4 rgba = unpackUnorm4x8(blobWord(cell.base, word + k));
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
// ask for chunks it lacks.
//
// The walk keeps its path: the node of every level down to the current cell, with its chunk.
// From one cell to the next it climbs only to their deepest common ancestor (the highest bit in
// which the two cells' grid coordinates differ) and descends from there, one node record (one
// load) a level. A node is drawn in place of what is below it when its error (node records'
// codes; a cut node's is its chunk's) covers less than P.lod.x pixels at the ray's distance, or
// when the chunk below it is not resident (which `request` then asks for).
bool intersect(vec3 o, vec3 d, float tMin, float tMax, float side, bool strict, float distance,
               bool request, ISO_INOUT(Hit) hit) {
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
  uint pathNode[kGridLevels + 1u];
  uint pathChunk[kGridLevels + 1u];
  uint words = recordWords();
  LodRule lod = lodRule(0.0f, 0.0f);
  float lodDistance = -1.0f;  // the distance up to which `lod` holds
  ChunkView chunk = chunkView(P.options.z);
  useChunk(chunk.id);
  uint level = 0u;
  uint node = 0u;
  pathNode[0] = 0u;
  pathChunk[0] = chunk.id;
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
    // Down from the path's node at `level` to the cell that holds g.
    if (distance + t > lodDistance) {
      // The rule at this distance, kept until the distance grows by an eighth of an octave (the
      // error codes' step): a little finer than needed in between, never coarser.
      float pixel = P.eye.w * (distance + t);  // a pixel's width at the ray's distance
      lod = lodRule(pixel, P.lod.x * pixel);
      lodDistance = (distance + t) * 1.0905077f;
    }
    Cell cell;
    cell.filled = false;
    for (;;) {
      uvec2 n = nodeRecord(chunk, node);
      uint mask = n.x & 0xFFu;
      if (mask == 0u || drawnInstead(lod, n.x, level)) {
        cell.filled = true;
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
      if ((n.x & kNodeCut) == 0u) {
        node = n.y + before;
      } else {
        uint childChunk = blobWord(chunk.base, n.y + 2u * before);
        uint childRoot = blobWord(chunk.base, n.y + 2u * before + 1u);
        if (chunkState(childChunk).x == kNotResident) {
          if (request) requestChunk(childChunk);
          cell.filled = true;  // the cut node's own patch until the chunk arrives
          break;
        }
        ChunkView below = chunkView(childChunk);
        // (A root index past the child's nodes would only come from a file whose chunks disagree.)
        if (childRoot >= blobWord(below.base, kBlobNodeCount)) {
          cell.filled = true;
          break;
        }
        chunk = below;
        useChunk(chunk.id);
        node = childRoot;
      }
      level += 1u;
      pathNode[level] = node;
      pathChunk[level] = chunk.id;
    }
    cell.level = level;
    cell.coord = g >> (kGridLevels - level);
    cell.base = chunk.base;
    cell.record = chunk.data + node * words;
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
      // Up to the deepest common ancestor of this cell and the next: the cells of a level are
      // the same for two grid points until their highest differing bit.
      uint differ = (first.x ^ g.x) | (first.y ^ g.y) | (first.z ^ g.z);
      level = kGridLevels - 1u - uint(findMSB(differ));
      node = pathNode[level];
      if (pathChunk[level] != chunk.id) chunk = chunkView(pathChunk[level]);
    }
  }
  if (!found) return false;
  // The root in the bracket, once, on the hit cell's cubic.
  float size = 1.0f / float(1u << hitCell.level);
  vec3 lo = vec3(hitCell.coord) * size;
  vec3 ua = cellCoordinates(o, d, tIn, lo, size);
  vec3 ub = cellCoordinates(o, d, tOut, lo, size);
  Corners c = loadCorners(hitCell.base, hitCell.record);
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
