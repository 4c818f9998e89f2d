// Caustics by photon tracing: photons leave each light toward the content, follow its specular
// bounces (refraction through transparent material, mirror reflection) and are summed where they
// land on the ground into the caustic map, which shading reads (shade.h, causticIrradiance).
// Part of the tracer (trace.h); specs/viewer.md, "Caustics".
//
// The includer provides, besides what trace.h lists:
//   void depositCaustic(uint word, uint value);  an atomic add to a word of the caustic map
//
// Flux: lights do not fall off with distance (shade.h: a lit point receives the light's color
// times the cosine), so across the beam toward the content the irradiance is the light's color.
// The photons of a light sample the disc P.causticDisc (across the direction from the light,
// covering the content) uniformly: each carries color × disc area × cos / photons, the cosine
// being that of its direction to the disc's axis. A cell of the map sums what lands in it,
// divided by its area: the irradiance the caustic adds there. Photons that reach the ground
// without a specular bounce are the direct light, which shading computes itself: they are not
// summed.

// Sum a photon's power (irradiance × cell area, in the map's units) into the cell under p;
// fractions of a unit are rounded up or down at random (stochastic rounding: the expected sum
// is exact). Photons outside the map are lost.
void depositPhoton(vec3 p, vec3 power, ISO_INOUT(uint) rng) {
  vec2 cell = causticCell(p);
  float x = cell.x, y = cell.y;
  if (!(x >= 0.0f && y >= 0.0f && x < float(kCausticCells) && y < float(kCausticCells))) return;
  uint at = 3u * (uint(y) * kCausticCells + uint(x));
  float u = randomUnit(rng);
  vec3 units = min(power + vec3(u), vec3(4.0e9f));
  if (units.x >= 1.0f) depositCaustic(at, uint(units.x));
  if (units.y >= 1.0f) depositCaustic(at + 1u, uint(units.y));
  if (units.z >= 1.0f) depositCaustic(at + 2u, uint(units.z));
}

// Photon `index` (P.caustics.x a light, the lights in turn): from its light (a uniform point of
// an area light) toward a uniform point of the disc, through at most kPhotonBounces specular
// bounces, summed into the map where it lands on the ground after one at least. At a surface a
// photon outside transparent material is refracted or reflected at random in proportion to the
// material's transparency and reflectivity (its power scaled by their sum; all reflected where
// refraction is impossible), and lost on a diffuse one; inside, it is absorbed along the way
// and leaves, or is totally reflected, as radiance() treats rays. Its rays meet the finest level
// resident (lodPixels() is -1: no pixel sees them, and a coarser level's normals would bend the
// light elsewhere; the same map wherever the camera is), and ask for the chunks they lack when
// streaming is on.
void tracePhoton(uint index) {
  uint which = index / max(P.caustics.x, 1u);
  if (which >= kMaxLights) return;
  Light light = P.lights[which];
  uint kind = uint(light.position.w);
  if (kind == kLightNone) return;
  uint rng = hashUint(index * 0x2545f491u + 0x6a09e667u);
  vec3 o = vec3(light.position.x, light.position.y, light.position.z);
  if (kind == kLightArea)
    o += (randomUnit(rng) - 0.5f) * vec3(light.u.x, light.u.y, light.u.z) +
         (randomUnit(rng) - 0.5f) * vec3(light.v.x, light.v.y, light.v.z);
  vec3 center = vec3(P.causticDisc.x, P.causticDisc.y, P.causticDisc.z);
  float radius = P.causticDisc.w;
  vec3 axis = center - o;
  float far = length(axis);
  if (!(far > radius)) return;  // a light inside the content's sphere sends none
  axis = axis / far;
  vec3 a = abs(axis.x) < 0.9f ? vec3(1.0f, 0.0f, 0.0f) : vec3(0.0f, 1.0f, 0.0f);
  vec3 e1 = normalize(cross(axis, a));
  vec3 e2 = cross(axis, e1);
  float rho = radius * sqrt(randomUnit(rng));
  float phi = 6.2831853f * randomUnit(rng);
  vec3 d = normalize(center + rho * (cos(phi) * e1 + sin(phi) * e2) - o);
  vec3 u = vec3(P.causticU.x, P.causticU.y, P.causticU.z);
  float perCell = dot(u, u);  // 1 / the cell's area
  vec3 power = vec3(light.color.x, light.color.y, light.color.z) *
               (3.14159265f * radius * radius * dot(d, axis) / float(max(P.caustics.x, 1u)) *
                perCell * kCausticScale);
  float eta = P.medium.x;
  float offset = P.lod.y;
  vec3 absorption = vec3(P.medium.y, P.medium.z, P.medium.w);
  bool request = (P.options.x & kOptionRequests) != 0u;
  float side = 0.0f;
  bool inMedium = false;
  float path = 0.0f;
  for (uint bounce = 0u; bounce <= kPhotonBounces; ++bounce) {
    Hit hit;
    if (!traceScene(o, d, 0.0f, 1e30f, side, false, path, request, hit)) return;
    vec3 p = o + d * hit.t;
    path += hit.t;
    if (onGround(hit)) {
      if (bounce > 0u) depositPhoton(p, power, rng);
      return;
    }
    if (bounce == kPhotonBounces) return;
    vec3 n = hit.from * hit.normal;  // facing the photon
    if (!inMedium) {
      float transparency = hitTransparency(hit);
      float mirror = hitReflectivity(hit);
      vec3 r = refract(d, n, 1.0f / eta);
      if (!(dot(r, r) > 0.0f)) {
        mirror += transparency;
        transparency = 0.0f;
      }
      float specular = transparency + mirror;
      if (!(specular > 0.0f)) return;  // a diffuse surface
      power *= specular;
      if (randomUnit(rng) * specular < transparency) {
        o = p - n * offset;
        d = normalize(r);
        side = -hit.from;
        inMedium = true;
      } else {
        o = p + n * offset;
        d = reflect(d, n);
        side = hit.from;
      }
    } else {
      power *= exp(-absorption * hit.t);
      vec3 r = refract(d, n, eta);
      bool leaves = dot(r, r) > 0.0f;
      o = leaves ? p - n * offset : p + n * offset;
      d = leaves ? normalize(r) : reflect(d, n);
      side = leaves ? -hit.from : hit.from;
      inMedium = !leaves;
    }
  }
}
