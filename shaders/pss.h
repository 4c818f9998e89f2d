// Point set surfaces (PSS; Adamson and Alexa's ray tracing of them, as in Tejada, Schafhitzel and
// Ertl's GPU ray tracer, specs/viewer.md "Point set surfaces"): each point keeps a local bivariate
// polynomial over its tangent plane, g(x, y) = A x² + B y² + C x y + D, valid inside its trust
// region, a ball of radius b around the point. Compiled as GLSL and as C++ (the includer defines
// ISO_INOUT and brings glm's names in).
//
// A patch is four vec4s: (origin, b), (normal n, D), (tangent u, A), (B, C, 0, 0); the
// bitangent is v = n × u, and a point origin + x u + y v + z n lies on the polynomial where
// z = g(x, y).

// The height of the polynomial minus z, along the ray o + t d in the patch's frame: a t² + b t
// + c. Returns whether the ray meets the polynomial at some t in (tMin, tMax) inside the trust
// region; t is the nearest such, and `normal` the polynomial's unit normal there (world, on the
// side of n).
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
  float roots[2];
  int count = 0;
  if (abs(a) < 1e-12f * max(abs(b), 1e-30f)) {
    if (b == 0.0f) return false;
    roots[0] = -c / b;
    count = 1;
  } else {
    float disc = b * b - 4.0f * a * c;
    if (disc < 0.0f) return false;
    // The numerically stable pair.
    float s = sqrt(disc);
    float q = -0.5f * (b + (b >= 0.0f ? s : -s));
    float t0 = q / a, t1 = q != 0.0f ? c / q : t0;
    roots[0] = min(t0, t1);
    roots[1] = max(t0, t1);
    count = 2;
  }
  float b2 = origin.w * origin.w;
  for (int k = 0; k < count; ++k) {
    float s = roots[k];
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
