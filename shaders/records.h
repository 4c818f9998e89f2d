// Chunks in the page pool: words of a chunk, the node that holds a point of the frame (walking
// down from the root across chunks), and a surface cell's corner record. Part of the tracer
// (trace.h, which lists what the includer provides).

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
