// Camera rays a tile at a time: a cone from the eye that holds every camera ray of a tile of
// pixels is traced through the octree, and the tile's rays start where it first meets a node
// that is not empty (intersect's tMin). The walk from the eye to the surface, most of a camera
// ray's cells (3/4 of them on the bunny and the lion, 7/8 on the 10M dragon), is then done once
// a tile instead of once a pixel, and tiles of sky trace nothing. Part of the tracer (trace.h).
//
// The pictures do not change, bytes included: a ray that starts in an empty cell walks, from that
// cell's exit on, the cells it would have walked from the eye (the cell a walk visits depends on
// its grid point and on its distance's level-of-detail rule alone: rays.h, updateLod and visit).

// Where the axis eye + axis·s enters the box [lo, lo + size]^3 grown by the cone's reach there:
// the cone's sine times the distance from the eye to the box's farthest point, plus a margin of
// 1e-5 (1 + that distance) for the rounding of the rays' points. -1 when it misses the box.
float coneEntry(vec3 eye, vec3 inv, float sine, vec3 lo, float size) {
  vec3 hi = lo + vec3(size);
  float far = length(max(abs(lo - eye), abs(hi - eye)));
  float reach = sine * far + 1e-5f * (1.0f + far);
  vec3 a = (lo - vec3(reach) - eye) * inv;
  vec3 b = (hi + vec3(reach) - eye) * inv;
  vec3 near = min(a, b);
  vec3 farPlane = max(a, b);
  float sNear = max(max(near.x, near.y), max(near.z, 0.0f));
  float sFar = min(farPlane.x, min(farPlane.y, farPlane.z));
  return sNear <= sFar ? sNear : -1.0f;
}

// The distance from the eye before which every ray within the cone (unit axis, sine of its half
// angle) passes through empty cells only, whatever the level of detail; 1e30 when the cone meets
// no node. A front-to-back walk of the nodes the cone meets, from the top chunk, that stops at a
// node (its entry is a candidate) when it is a leaf, when it is not wider than the cone there,
// when the coarsest level-of-detail rule in it may draw it in place of its children, or when a
// child's chunk is not resident (a ray there draws the node); the nearest candidate is the
// answer. It looks at kConeNodes nodes at most and keeps kConeStack waiting; past either, the
// entries of the nodes it did not look at are candidates too.
float coneStart(vec3 eye, vec3 axis, float sine) {
  vec3 dir = nonzeroDirection(axis);
  vec3 inv = vec3(1.0f) / dir;
  float best = 1e30f;
  float rootEntry = coneEntry(eye, inv, sine, vec3(0.0f), 1.0f);
  if (rootEntry < 0.0f) return best;
  uvec4 waiting[kConeStack];  // node, chunk, level, entry (float bits)
  uvec3 waitingCell[kConeStack];
  waiting[0] = uvec4(0u, P.options.z, 0u, floatBitsToUint(rootEntry));
  waitingCell[0] = uvec3(0u);
  uint count = 1u;
  // Children are pushed farthest first, so that the nearest is looked at first.
  uint nearest = (dir.x < 0.0f ? 1u : 0u) | (dir.y < 0.0f ? 2u : 0u) | (dir.z < 0.0f ? 4u : 0u);
  for (uint turn = 0u; turn < kConeNodes && count > 0u; ++turn) {
    count -= 1u;
    uvec4 item = waiting[count];
    uvec3 coord = waitingCell[count];
    float entry = uintBitsToFloat(item.w);
    if (entry >= best) continue;
    ChunkView chunk = chunkView(item.y);
    uvec2 n = nodeRecord(chunk, item.x);
    uint mask = n.x & 0xFFu;
    uint level = item.z;
    float size = 1.0f / float(1u << level);
    vec3 lo = vec3(coord) * size;
    float far = length(max(abs(lo - eye), abs(lo + vec3(size) - eye)));
    float pixel = P.eye.w * far;
    if (mask == 0u || size <= sine * far || level + 1u >= kGridLevels ||
        drawnInstead(lodRule(pixel, P.lod.x * pixel), n.x, level)) {
      best = entry;
      continue;
    }
    float childSize = 0.5f * size;
    for (uint i = 0u; i < 8u; ++i) {
      uint octant = (7u - i) ^ nearest;
      if (((mask >> octant) & 1u) == 0u) continue;
      uvec3 childCoord = 2u * coord + uvec3(octant & 1u, (octant >> 1u) & 1u, octant >> 2u);
      float s = coneEntry(eye, inv, sine, vec3(childCoord) * childSize, childSize);
      if (s < 0.0f || s >= best) continue;
      uint before = uint(bitCount(mask & ((1u << octant) - 1u)));
      uint child = n.y + before;
      uint childChunk = item.y;
      if ((n.x & kNodeCut) != 0u) {
        childChunk = blobWord(chunk.base, n.y + 2u * before);
        child = blobWord(chunk.base, n.y + 2u * before + 1u);
        if (chunkState(childChunk).x == kNotResident ||
            child >= blobWord(chunkView(childChunk).base, kBlobNodeCount)) {
          best = min(best, entry);  // rays there draw this node
          continue;
        }
      }
      if (count == kConeStack) {
        best = min(best, s);
        continue;
      }
      waiting[count] = uvec4(child, childChunk, level + 1u, floatBitsToUint(s));
      waitingCell[count] = childCoord;
      count += 1u;
    }
  }
  for (uint i = 0u; i < count; ++i) best = min(best, uintBitsToFloat(waiting[i].w));
  return best;
}

// Where the camera rays of the pixels [x0, x1) × [y0, y1) start (any sample in them): the start
// of the cone around them, or 0 when tile cones are off.
float tileStart(uint x0, uint y0, uint x1, uint y1) {
  if ((P.options.x & kOptionTileCones) == 0u) return 0.0f;
  vec3 c0 = cameraDirection(x0, y0, 0.0f, 0.0f);
  vec3 c1 = cameraDirection(x1 - 1u, y0, 1.0f, 0.0f);
  vec3 c2 = cameraDirection(x0, y1 - 1u, 0.0f, 1.0f);
  vec3 c3 = cameraDirection(x1 - 1u, y1 - 1u, 1.0f, 1.0f);
  vec3 axis = normalize(c0 + c1 + c2 + c3);
  // The cone around the four corners holds the rectangle between them (its section by the
  // image plane is an ellipse, convex). Sines from cross products (accurate for small angles),
  // rounded up.
  float sine = max(max(length(cross(axis, c0)), length(cross(axis, c1))),
                   max(length(cross(axis, c2)), length(cross(axis, c3))));
  sine = sine * 1.001f + 1e-6f;
  return coneStart(vec3(P.eye.x, P.eye.y, P.eye.z), axis, sine);
}
