// Splats: the kept points of a file as oriented disks, with deep blending of the disks a ray
// crosses in a small depth window behind the nearest one. Part of the tracer (trace.h); layouts
// in shared.h, the method in specs/viewer.md ("Splats").
//
// A ray walks the splat index (a tree over the points chunks: subsample chunks above the chunks
// they thin out) and, in each chunk it draws, the chunk's box tree down to groups of 4 disks;
// both walks go without a stack. A
// subsample chunk is drawn in place of its children when its largest radius is below P.lod.x
// pixels at the ray's distance, and in place of a child that is not resident (only inside that
// child's box, and the ray asks for the child). Two walks: the first finds the nearest disk, the
// second blends every disk met within P.splat.x radii of it behind it.

// What the walks gather: the nearest hit, then the blended sums.
struct SplatSum {
  bool leaving;   // the ray leaves a hit (shadow, reflected, refracted): disks nearer than their
                  // radius are the surface it leaves
  float nearest;  // t of the nearest disk (first walk)
  float radius;   // its radius
  float weight;   // blending sums (second walk)
  float t;
  vec3 center;
  vec3 normal;
  vec3 color;
};

// The entry of the ray o + t·d (inv = 1/d) into the box [lo, hi] within [tMin, tMax], or a
// negative value when it misses it.
float boxEntry(vec3 o, vec3 inv, vec3 lo, vec3 hi, float tMin, float tMax) {
  vec3 a = (lo - o) * inv;
  vec3 b = (hi - o) * inv;
  vec3 near = min(a, b);
  vec3 far = max(a, b);
  float t0 = max(tMin, max(near.x, max(near.y, near.z)));
  float t1 = min(tMax, min(far.x, min(far.y, far.z)));
  return t0 <= t1 ? t0 : -1.0f;
}

vec3 blobVec3(ISO_ADDRESS base, uint word) {
  return vec3(uintBitsToFloat(blobWord(base, word)), uintBitsToFloat(blobWord(base, word + 1u)),
              uintBitsToFloat(blobWord(base, word + 2u)));
}

// Disk `record` of a splat blob against the ray, for t in [tMin, tMax] and a hit point inside
// [clipLo, clipHi]. The first walk (!blend) keeps the nearest; the second adds the disk to the
// blend with the weight 1 - (distance from its center / radius)^2.
void splatDisk(ISO_ADDRESS base, uint record, vec3 o, vec3 d, float tMin, float tMax,
               vec3 clipLo, vec3 clipHi, bool blend, ISO_INOUT(SplatSum) s) {
  vec3 c = blobVec3(base, record);
  float r = uintBitsToFloat(blobWord(base, record + 3u));
  uint rgba = blobWord(base, record + 5u);
  vec3 n;
  float t;
  if ((rgba >> 24u) != 0u) {
    n = decodeOctahedral(unpackSnorm2x16(blobWord(base, record + 4u)));
    float dn = dot(d, n);
    if (abs(dn) < 1e-7f) return;
    t = dot(c - o, n) / dn;
  } else {  // no normal: a disk facing the ray
    n = -d;
    t = dot(c - o, d);
  }
  if (!(t >= tMin && t <= tMax) || (s.leaving && t < r)) return;
  vec3 p = o + d * t;
  vec3 q = p - c;
  float q2 = dot(q, q);
  if (q2 > r * r) return;
  if (p.x < clipLo.x || p.y < clipLo.y || p.z < clipLo.z || p.x > clipHi.x || p.y > clipHi.y ||
      p.z > clipHi.z)
    return;
  if (!blend) {
    s.nearest = t;
    s.radius = r;
    return;
  }
  float w = max(1.0f - q2 / (r * r), 1e-3f);
  s.weight += w;
  s.t += w * t;
  s.center += w * c;
  s.normal += w * (dot(n, d) > 0.0f ? -n : n);  // facing the ray
  s.color += w * vec3(linearOfSrgb(rgba & 0xFFu), linearOfSrgb((rgba >> 8u) & 0xFFu),
                      linearOfSrgb((rgba >> 16u) & 0xFFu));
}

// The disks of one resident chunk: its box tree, depth first without a stack (the tree is
// implicit: a box's children are 4i to 4i + 3 of the level below, so the walk goes on to the next
// sibling, or up to the parent's next one). Arrays indexed per invocation go through memory on
// CPUs such as lavapipe's (specs/viewer.md, "Splats").
void splatChunk(ISO_ADDRESS base, vec3 o, vec3 d, vec3 inv, float tMin, float tMax, vec3 clipLo,
                vec3 clipHi, bool blend, ISO_INOUT(SplatSum) s) {
  uint n = blobWord(base, kSplatCount);
  uint levels = blobWord(base, kSplatLevels);
  uint records = blobWord(base, kSplatPoints);
  if (n == 0u || levels == 0u) return;
  uint top = levels - 1u;
  uint level = top;
  uint index = 0u;
  for (;;) {
    uint at = blobWord(base, kSplatLevelFirst + level) + kSplatBoxWords * index;
    float end = blend ? tMax : min(tMax, s.nearest);
    bool hit = boxEntry(o, inv, blobVec3(base, at), blobVec3(base, at + 3u), tMin, end) >= 0.0f;
    if (hit && level > 0u) {  // down to the first child
      level -= 1u;
      index *= kSplatBranch;
      continue;
    }
    if (hit) {
      uint first = kSplatBranch * index;
      uint last = min(first + kSplatBranch, n);
      for (uint k = first; k < last; ++k)
        splatDisk(base, records + kSplatRecordWords * k, o, d, tMin, blend ? tMax : s.nearest,
                  clipLo, clipHi, blend, s);
    }
    // On to the next sibling, or up until there is one.
    for (;;) {
      if (level == top) return;
      uint next = index + 1u;
      if (next % kSplatBranch != 0u && next < blobWord(base, kSplatLevelCount + level)) {
        index = next;
        break;
      }
      index /= kSplatBranch;
      level += 1u;
    }
  }
}

// One walk of the splat index over [tMin, tMax], in its preorder without a stack: a node that
// the ray misses, or whose chunk is drawn, is skipped with its subtree (its `skip` word).
void splatWalk(vec3 o, vec3 d, vec3 inv, float tMin, float tMax, float distance, bool request,
               bool blend, ISO_INOUT(SplatSum) s) {
  ISO_ADDRESS index = blobBase(chunkState(P.splatIndex.x).x);
  uint count = blobWord(index, kSplatCount);
  uint nodes = blobWord(index, kSplatIndexNodes);
  vec3 everywhere = vec3(1e30f);
  uint i = 0u;
  while (i < count) {
    uint at = nodes + kSplatNodeWords * i;
    uint chunk = blobWord(index, at + 6u);
    uint skip = blobWord(index, at + 7u);
    uint parent = blobWord(index, at + 8u);
    float radius = uintBitsToFloat(blobWord(index, at + 9u));
    vec3 lo = blobVec3(index, at);
    vec3 hi = blobVec3(index, at + 3u);
    float end = blend ? tMax : min(tMax, s.nearest);
    float entry = boxEntry(o, inv, lo, hi, tMin, end);
    if (entry < 0.0f) {
      i = skip;
      continue;
    }
    if (chunk != kNotResident && chunkState(chunk).x == kNotResident) {
      // Not resident: asked for, and the parent's chunk drawn in its place, inside its box.
      if (request) requestChunk(chunk);
      if (parent != kNotResident && chunkState(parent).x != kNotResident)
        splatChunk(blobBase(chunkState(parent).x), o, d, inv, tMin, tMax, lo, hi, blend, s);
      i = skip;
      continue;
    }
    bool leaf = skip == i + 1u;
    bool coarseEnough = radius <= lodPixels() * P.eye.w * (distance + entry);
    if (chunk != kNotResident && (leaf || coarseEnough)) {
      useChunk(chunk);
      splatChunk(blobBase(chunkState(chunk).x), o, d, inv, tMin, tMax, -everywhere, everywhere,
                 blend, s);
      i = skip;
      continue;
    }
    i += 1u;  // into its children
  }
}

// The splats' first hit on the ray o + t·d, t in [tMin, tMax]: the blend of the disks within the
// depth window behind the nearest one (position, normal facing the ray, color). `distance` is the
// path length before o (level of detail; a ray with a path before it leaves a hit, and disks
// nearer to its origin than their radius do not count); `request` lets the ray ask for chunks it
// lacks.
bool intersectSplats(vec3 o, vec3 d, float tMin, float tMax, float distance, bool request,
                     ISO_INOUT(Hit) hit) {
  vec3 inv = vec3(1.0f) / nonzeroDirection(d);
  SplatSum s;
  s.leaving = distance > 0.0f;
  s.nearest = tMax;
  s.radius = 0.0f;
  s.weight = 0.0f;
  s.t = 0.0f;
  s.center = vec3(0.0f);
  s.normal = vec3(0.0f);
  s.color = vec3(0.0f);
  splatWalk(o, d, inv, tMin, tMax, distance, request, false, s);
  if (!(s.radius > 0.0f)) return false;
  float window = P.splat.x * s.radius;
  splatWalk(o, d, inv, s.nearest, s.nearest + window, distance, false, true, s);
  if (!(s.weight > 0.0f)) return false;  // (the nearest disk is always in the blend)
  hit.from = 1.0f;
  hit.normal = dot(s.normal, s.normal) > 0.0f ? normalize(s.normal) : -d;
  // The hit is where the ray meets the blended plane (the disks' mean center and normal): the
  // mean of the disks' own hits would lean toward the nearest ones, most at grazing angles. Where
  // the ray runs along that plane, the mean of the hits; never more than the window from the
  // nearest disk.
  vec3 center = s.center / s.weight;
  float facing = dot(d, hit.normal);
  hit.t = facing < -0.05f ? dot(center - o, hit.normal) / facing : s.t / s.weight;
  hit.t = clamp(hit.t, max(tMin, s.nearest - window), s.nearest + window);
  hit.color = (P.options.x & kOptionColors) != 0u ? s.color / s.weight
                                                  : vec3(P.albedo.x, P.albedo.y, P.albedo.z);
  hit.occlusion = 1.0f;
  hit.irradiance = vec4(0.0f);
  return true;
}

// Whether a hit is on the ground plane (its normal is the plane's, exactly: traceScene sets it).
bool onGround(Hit hit) {
  return (P.options.x & kOptionGround) != 0u && hit.normal.x == P.ground.x &&
         hit.normal.y == P.ground.y && hit.normal.z == P.ground.z;
}

// The first hit of a ray on what the frame draws: the surface (intersect, rays.h), the splats, a
// point set surface (pss.h), the nearest of them; then the ground plane when it is nearer (seen
// from above only).
bool traceScene(vec3 o, vec3 d, float tMin, float tMax, float side, bool strict, float distance,
                bool request, ISO_INOUT(Hit) hit) {
  bool found = false;
  bool splats = splatsCompiled() && (P.options.x & kOptionSplats) != 0u;
  if (!splats || (P.options.x & kOptionNoSurface) == 0u)
    found = intersect(o, d, tMin, tMax, side, strict, distance, request, hit);
  if (splats) {
    Hit splat;
    if (intersectSplats(o, d, tMin, found ? hit.t : tMax, distance, request, splat)) {
      hit = splat;
      found = true;
    }
  }
  // A point set surface: its normals point out of it, so a ray meets it from outside where it
  // runs against its normal.
  if (pssCompiled() && (P.options.x & kOptionPss) != 0u) {
    float t = 0.0f;
    vec3 n = vec3(0.0f);
    uint point = 0u;
    int projections = 0;
    // (Rays that leave a surface skip pssSkip(): neighbouring polynomials of one surface differ
    // by more than the tracer's offset.)
    if (pssHit(o, d, max(tMin, distance > 0.0f ? pssSkip() : 0.0f), found ? hit.t : tMax,
               pssExact(), t, n, point, projections)) {
      hit.t = t;
      hit.from = dot(n, d) < 0.0f ? 1.0f : -1.0f;
      hit.normal = n;
      hit.color = pssColor(point);
      hit.occlusion = 1.0f;
      hit.irradiance = vec4(0.0f);
      found = true;
    }
  }
  if ((P.options.x & kOptionGround) != 0u) {
    vec3 n = vec3(P.ground.x, P.ground.y, P.ground.z);
    float dn = dot(d, n);
    float t = dn < 0.0f ? (P.ground.w - dot(o, n)) / dn : -1.0f;
    if (t >= tMin && t <= (found ? hit.t : tMax)) {
      hit.t = t;
      hit.from = 1.0f;
      hit.normal = n;
      hit.color = vec3(P.groundColor.x, P.groundColor.y, P.groundColor.z);
      hit.occlusion = 1.0f;
      hit.irradiance = vec4(0.0f);
      found = true;
    }
  }
  return found;
}
