// The surface inside one cell: the ray's local coordinates, the trilinear interpolation along
// the ray as a cubic, its first sign change and the root there, the gradient. Part of the tracer
// (trace.h).

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

// A direction with no zero component (each below 1e-12 in size set to 1e-12), so that its inverse
// is finite: the slab tests of boxes divide by it.
vec3 nonzeroDirection(vec3 d) {
  vec3 dir = d;
  if (abs(dir.x) < 1e-12f) dir.x = 1e-12f;
  if (abs(dir.y) < 1e-12f) dir.y = 1e-12f;
  if (abs(dir.z) < 1e-12f) dir.z = 1e-12f;
  return dir;
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
