// Point set surfaces (PSS; Adamson and Alexa's ray tracing of them, as in Tejada, Schafhitzel and
// Ertl's GPU ray tracer; specs/viewer.md, "Point set surfaces"): each point keeps a local
// bivariate polynomial over its tangent plane, g(x, y) = A x² + B y² + C x y + D, valid inside
// its trust region, a ball of radius b around the point; a uniform grid lists the points of each
// cell and the trust regions reaching into it. Compiled as GLSL and as C++ (the includer defines
// ISO_INOUT, brings glm's names in and provides the accessors below).
//
// A patch is four vec4s: (origin, b), (normal n, D), (tangent u, A), (B, C, 0, 0); the
// bitangent is v = n × u, and a point origin + x u + y v + z n lies on the polynomial where
// z = g(x, y).
//
// The includer's accessors:
//   vec3 pssGridLo(); float pssGridSide(); ivec3 pssGridDims();
//   uint pssPointStart(uint cell); uint pssPointAt(uint k);  // a cell's points: [start, next start)
//   uint pssReachStart(uint cell); uint pssReachAt(uint k);  // the trust regions reaching in
//   vec3 pssPosition(uint i); vec3 pssNormal(uint i); float pssH(uint i);
//   vec4 pssPatch(uint i, int part);                         // part 0 to 3, as above
//   vec4 pssSettings();  // (trust: b / h, reach: neighbours' distance / h, tolerance / h,
//                        //  projections at most)

// The height of the polynomial minus z, along the ray o + t d in the patch's frame: a t² + b t
// + c. Returns whether the ray meets the polynomial at some t in (tMin, tMax) inside the trust
// region; t is the nearest such, and `hitNormal` the polynomial's unit normal there (world, on
// the side of n).
bool pssIntersect(vec4 origin, vec4 normal, vec4 tangent, vec4 coefficients, vec3 o, vec3 d,
                  float tMin, float tMax, ISO_INOUT(float) t, ISO_INOUT(vec3) hitNormal) {
  vec3 n = vec3(normal), u = vec3(tangent), v = cross(n, u);
  vec3 r = o - vec3(origin);
  // The ray in the patch's frame.
  float ox = dot(r, u), oy = dot(r, v), oz = dot(r, n);
  float dx = dot(d, u), dy = dot(d, v), dz = dot(d, n);
  float A = tangent.w, B = coefficients.x, C = coefficients.y, D = normal.w;
  float a = A * dx * dx + B * dy * dy + C * dx * dy;
  float b = 2.0f * A * ox * dx + 2.0f * B * oy * dy + C * (ox * dy + oy * dx) - dz;
  float c = A * ox * ox + B * oy * oy + C * ox * oy + D - oz;
  // The roots, nearer first (one when a vanishes).
  float r0 = 0.0f, r1 = 0.0f;
  int count = 2;
  if (abs(a) < 1e-12f * max(abs(b), 1e-30f)) {
    if (b == 0.0f) return false;
    r0 = -c / b;
    count = 1;
  } else {
    float disc = b * b - 4.0f * a * c;
    if (disc < 0.0f) return false;
    // The numerically stable pair.
    float s = sqrt(disc);
    float q = -0.5f * (b + (b >= 0.0f ? s : -s));
    float t0 = q / a, t1 = q != 0.0f ? c / q : t0;
    r0 = min(t0, t1);
    r1 = max(t0, t1);
  }
  float b2 = origin.w * origin.w;
  for (int k = 0; k < count; ++k) {
    float s = k == 0 ? r0 : r1;
    if (!(s > tMin && s < tMax)) continue;
    vec3 local = vec3(ox + s * dx, oy + s * dy, oz + s * dz);
    if (dot(local, local) > b2) continue;  // outside the trust region
    t = s;
    // The gradient of z - g(x, y), in the frame, then in the world.
    float gx = 2.0f * A * local.x + C * local.y, gy = 2.0f * B * local.y + C * local.x;
    hitNormal = normalize(n - gx * u - gy * v);
    return true;
  }
  return false;
}

ivec3 pssCellOf(vec3 p) {
  return clamp(ivec3(floor((p - pssGridLo()) / pssGridSide())), ivec3(0), pssGridDims() - 1);
}

uint pssCellIndex(ivec3 c) {
  ivec3 dims = pssGridDims();
  return (uint(c.z) * uint(dims.y) + uint(c.y)) * uint(dims.x) + uint(c.x);
}

// The fast mode: the nearest hit of o + t d (d unit), t in (tMin, tMax), with a stored polynomial
// inside its trust region, walking the grid's cells along the ray (Amanatides and Woo) and testing
// the trust regions listed in each; `point` is the patch's point.
bool pssFirstHit(vec3 o, vec3 d, float tMin, float tMax, ISO_INOUT(float) t,
                 ISO_INOUT(vec3) hitNormal, ISO_INOUT(uint) point) {
  vec3 lo = pssGridLo();
  float side = pssGridSide();
  ivec3 dims = pssGridDims();
  vec3 hi = lo + vec3(dims) * side;
  // The ray's span inside the grid's box (slabs; a zero component divides to ±infinity).
  vec3 inv = vec3(1.0f) / d;
  vec3 ta = (lo - o) * inv, tb = (hi - o) * inv;
  vec3 tNear = min(ta, tb), tFar = max(ta, tb);
  float t0 = max(tMin, max(tNear.x, max(tNear.y, tNear.z)));
  float t1 = min(tMax, min(tFar.x, min(tFar.y, tFar.z)));
  if (!(t0 <= t1)) return false;
  // Amanatides and Woo's walk, without indexing a vector by a variable (costly in lavapipe).
  ivec3 cell = pssCellOf(o + t0 * d);
  vec3 sign = vec3(greaterThan(d, vec3(0.0f))) - vec3(lessThan(d, vec3(0.0f)));
  ivec3 step = ivec3(sign);
  vec3 boundary = lo + (vec3(cell) + max(sign, vec3(0.0f))) * side;
  vec3 next = mix(vec3(3.0e38f), (boundary - o) * inv, notEqual(sign, vec3(0.0f)));
  vec3 delta = mix(vec3(3.0e38f), abs(vec3(side) * inv), notEqual(sign, vec3(0.0f)));
  bool found = false;
  float best = tMax;
  for (;;) {
    uint c = pssCellIndex(cell);
    uint end = pssReachStart(c + 1u);
    for (uint k = pssReachStart(c); k < end; ++k) {
      uint i = pssReachAt(k);
      float s = 0.0f;
      vec3 normal = vec3(0.0f);
      if (pssIntersect(pssPatch(i, 0), pssPatch(i, 1), pssPatch(i, 2), pssPatch(i, 3), o, d, tMin,
                       best, s, normal)) {
        best = s;
        t = s;
        hitNormal = normal;
        point = i;
        found = true;
      }
    }
    float leave = min(next.x, min(next.y, next.z));
    // Every trust region reaching past this cell's exit was tested: a hit before it is the first.
    if (found && best <= leave) return true;
    if (leave > t1) return found;
    // The axis whose boundary comes first (x before y before z on ties).
    vec3 axis = vec3(next.x == leave, next.x != leave && next.y == leave,
                     next.x != leave && next.y != leave);
    cell += ivec3(axis) * step;
    if (any(lessThan(cell, ivec3(0))) || any(greaterThanEqual(cell, dims))) return found;
    next += axis * delta;
  }
  return found;
}

// The polynomial fitted at x by weighted least squares over the points within reach × h of it
// (Gaussian weights of width h, the nearest point's): its plane H through their weighted mean,
// across their weighted normal, its frame's origin x's foot on H. False where no point is near.
bool pssFit(vec3 x, ISO_INOUT(vec4) origin, ISO_INOUT(vec4) normal, ISO_INOUT(vec4) tangent,
            ISO_INOUT(vec4) coefficients) {
  vec4 settings = pssSettings();
  float side = pssGridSide();
  // The nearest point within a cell: its h.
  float h = 0.0f, nearest = 3.0e38f;
  vec3 reference = vec3(0.0f);
  ivec3 a = pssCellOf(x - side), b = pssCellOf(x + side);
  for (int cz = a.z; cz <= b.z; ++cz)
    for (int cy = a.y; cy <= b.y; ++cy)
      for (int cx = a.x; cx <= b.x; ++cx) {
        uint c = pssCellIndex(ivec3(cx, cy, cz));
        uint end = pssPointStart(c + 1u);
        for (uint k = pssPointStart(c); k < end; ++k) {
          uint i = pssPointAt(k);
          vec3 r = pssPosition(i) - x;
          float d = dot(r, r);
          if (d < nearest) {
            nearest = d;
            h = pssH(i);
            reference = pssNormal(i);
          }
        }
      }
  if (!(h > 0.0f)) return false;
  float reach = settings.y * h, inv = 1.0f / (h * h);
  a = pssCellOf(x - reach);
  b = pssCellOf(x + reach);
  // Pass 1: the weighted normal and mean.
  vec3 sumNormal = vec3(0.0f), sumPosition = vec3(0.0f);
  float weights = 0.0f;
  int count = 0;
  for (int cz = a.z; cz <= b.z; ++cz)
    for (int cy = a.y; cy <= b.y; ++cy)
      for (int cx = a.x; cx <= b.x; ++cx) {
        uint c = pssCellIndex(ivec3(cx, cy, cz));
        uint end = pssPointStart(c + 1u);
        for (uint k = pssPointStart(c); k < end; ++k) {
          uint i = pssPointAt(k);
          vec3 r = pssPosition(i) - x;
          float d = dot(r, r);
          if (d > reach * reach) continue;
          float w = exp(-d * inv);
          // Normals of either sign (estimated, unoriented) count on the side of the nearest's.
          vec3 ni = pssNormal(i);
          sumNormal += w * (dot(ni, reference) < 0.0f ? -ni : ni);
          sumPosition += w * r;
          weights += w;
          ++count;
        }
      }
  if (count < 3 || dot(sumNormal, sumNormal) < 1e-24f * weights * weights) return false;
  vec3 n = normalize(sumNormal);
  vec3 mean = sumPosition / weights;  // from x
  vec3 q = x + dot(mean, n) * n;      // x's foot on H
  vec3 u = normalize(cross(n, abs(n.x) < 0.6f ? vec3(1, 0, 0) : vec3(0, 1, 0)));
  vec3 v = cross(n, u);
  // Pass 2: the normal equations of g over H, in units of h (well conditioned in float).
  float m[4][5];
  for (int r = 0; r < 4; ++r)
    for (int k = 0; k < 5; ++k) m[r][k] = 0.0f;
  for (int cz = a.z; cz <= b.z; ++cz)
    for (int cy = a.y; cy <= b.y; ++cy)
      for (int cx = a.x; cx <= b.x; ++cx) {
        uint c = pssCellIndex(ivec3(cx, cy, cz));
        uint end = pssPointStart(c + 1u);
        for (uint k = pssPointStart(c); k < end; ++k) {
          uint i = pssPointAt(k);
          vec3 p = pssPosition(i);
          float d = dot(p - x, p - x);
          if (d > reach * reach) continue;
          float w = exp(-d * inv);
          vec3 r = (p - q) / h;
          float X = dot(r, u), Y = dot(r, v), F = dot(r, n);
          float phi[4] = {X * X, Y * Y, X * Y, 1.0f};
          for (int row = 0; row < 4; ++row) {
            for (int col = 0; col < 4; ++col) m[row][col] += w * phi[row] * phi[col];
            m[row][4] += w * phi[row] * F;
          }
        }
      }
  // A little ridge on the quadratic terms keeps too few or collinear points solvable (they
  // then give nearly the plane).
  for (int r = 0; r < 3; ++r) m[r][r] += 1e-4f * m[3][3];
  // Gaussian elimination with partial pivoting.
  for (int col = 0; col < 4; ++col) {
    int pivot = col;
    for (int r = col + 1; r < 4; ++r)
      if (abs(m[r][col]) > abs(m[pivot][col])) pivot = r;
    for (int k = 0; k < 5; ++k) {
      float s = m[col][k];
      m[col][k] = m[pivot][k];
      m[pivot][k] = s;
    }
    if (abs(m[col][col]) < 1e-30f) return false;
    for (int r = col + 1; r < 4; ++r) {
      float f = m[r][col] / m[col][col];
      for (int k = col; k < 5; ++k) m[r][k] -= f * m[col][k];
    }
  }
  float g[4];
  for (int r = 3; r >= 0; --r) {
    float s = m[r][4];
    for (int k = r + 1; k < 4; ++k) s -= m[r][k] * g[k];
    g[r] = s / m[r][r];
  }
  // Back from units of h: A, B, C scale by 1 / h, D by h.
  origin = vec4(q, settings.x * h);
  normal = vec4(n, g[3] * h);
  tangent = vec4(u, g[0] / h);
  coefficients = vec4(g[1] / h, g[2] / h, 0.0f, 0.0f);
  return true;
}

// A ray's first hit: the fast mode's, and in the exact mode (exact) that hit projected onto the
// moving-least-squares surface (the fitted polynomial over the hit's foot) and the ray
// intersected again with the polynomial fitted there, until the projection moves less than the
// tolerance; outside that polynomial's trust region, the search goes on to the next stored
// polynomial along the ray. `projections` counts the fits.
bool pssHit(vec3 o, vec3 d, float tMin, float tMax, bool exact, ISO_INOUT(float) t,
            ISO_INOUT(vec3) hitNormal, ISO_INOUT(uint) point, ISO_INOUT(int) projections) {
  projections = 0;
  if (!pssFirstHit(o, d, tMin, tMax, t, hitNormal, point)) return false;
  if (!exact) return true;
  vec4 settings = pssSettings();
  for (int k = 0; k < int(settings.w); ++k) {
    vec3 x = o + t * d;
    vec4 P0, P1, P2, P3;
    if (!pssFit(x, P0, P1, P2, P3)) return true;
    ++projections;
    vec3 onSurface = vec3(P0) + P1.w * vec3(P1);
    float h = P0.w / settings.x;
    if (length(onSurface - x) < settings.z * h) {
      hitNormal = vec3(P1);  // the fitted polynomial's normal over its origin
      return true;
    }
    float s = 0.0f;
    vec3 normal = vec3(0.0f);
    if (pssIntersect(P0, P1, P2, P3, o, d, tMin, tMax, s, normal)) {
      t = s;
      hitNormal = normal;
      continue;
    }
    if (!pssFirstHit(o, d, t + 1e-4f * h, tMax, t, hitNormal, point)) return false;
  }
  return true;
}
