// Chunks in the page pool: a chunk's base address and regions, its node records, and a node's
// corner record. Part of the tracer (trace.h, which lists what the includer provides).

// A resident chunk as the traversal reads it: resolved once when a ray enters it.
struct ChunkView {
  uint id;
  ISO_ADDRESS base;  // the blob's first word
  uint nodes;        // the word of node record 0
  uint data;         // the word of corner record 0
};

ChunkView chunkView(uint chunk) {
  ChunkView v;
  v.id = chunk;
  v.base = blobBase(chunkState(chunk).x);
  v.nodes = blobWord(v.base, kBlobNodes);
  v.data = blobWord(v.base, kBlobData);
  return v;
}

// Node record i of the chunk, in one load: (childMask | flags | error code, link).
uvec2 nodeRecord(ChunkView v, uint i) { return blobPair(v.base, v.nodes + 2u * i); }

// Words of a corner record's distances.
uint distanceWords() {
  return floatDistances() ? kRecordFloatDistanceWords : kRecordDistanceWords;
}

// Words of a corner record.
uint recordWords() {
  uint words = distanceWords();
  if ((P.options.x & kOptionNormals) != 0u) words += kRecordNormalWords;
  if ((P.options.x & (kOptionColors | kOptionOcclusion)) != 0u) words += kRecordColorWords;
  if ((P.options.x & kOptionIrradiance) != 0u) words += kRecordIrradianceWords;
  return words;
}

// Which nodes may be drawn in place of their children at a ray's distance, where a pixel is
// `pixel` frame units wide: those whose error is at most `reach` and whose edge is at most
// kLodNodePixels pixels. A node at level L has edge 2^-L and error at most 2^-L · 2^((e - 128) / 8)
// (shared.h), so the test is on integers: L >= fromLevel and e <= maxCode + 8·L.
struct LodRule {
  int fromLevel;
  int maxCode;
};

LodRule lodRule(float pixel, float reach) {
  LodRule r;
  r.fromLevel = 64;  // none
  r.maxCode = -1;
  if (reach > 0.0f && pixel > 0.0f) {
    r.fromLevel = int(ceil(-log2(kLodNodePixels * pixel)));
    r.maxCode = int(floor(128.0f + 8.0f * log2(reach)));
  }
  return r;
}

bool drawnInstead(LodRule r, uint w0, uint level) {
  int code = int((w0 >> kNodeErrorShift) & 0xFFu);
  return int(level) >= r.fromLevel && code != 255 && code <= r.maxCode + 8 * int(level);
}

// A surface cell (a filled leaf, or a node drawn in place of what is below it) or an empty cell.
struct Cell {
  bool filled;
  uint level;
  uvec3 coord;       // cell coordinates at level
  ISO_ADDRESS base;  // the chunk holding the node
  uint record;       // word of the corner record (filled)
};

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

Corners loadCorners(ISO_ADDRESS base, uint record) {
  Corners c;
  if (floatDistances()) {
    c.d0 = vec4(uintBitsToFloat(blobWord(base, record)), uintBitsToFloat(blobWord(base, record + 1u)),
                uintBitsToFloat(blobWord(base, record + 2u)),
                uintBitsToFloat(blobWord(base, record + 3u)));
    c.d1 = vec4(uintBitsToFloat(blobWord(base, record + 4u)),
                uintBitsToFloat(blobWord(base, record + 5u)),
                uintBitsToFloat(blobWord(base, record + 6u)),
                uintBitsToFloat(blobWord(base, record + 7u)));
    return c;
  }
  uint shifts = blobWord(base, record + 2u);
  c.d0 = decodeDistances(blobWord(base, record), shifts);
  c.d1 = decodeDistances(blobWord(base, record + 1u), shifts >> 16u);
  return c;
}
