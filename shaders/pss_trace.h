// Ray tracing point set surfaces (pss.h; specs/viewer.md, "Point set surfaces"): a ray's color
// from its hits, lit by Phong with shadow rays through the grid (self-shadowing included), and
// followed through transparent surfaces along the refracted ray, each color channel with its own
// index of refraction (dispersion). Compiled as GLSL and as C++ after pss.h and pss_volume.h; the includer also
// provides:
//   uint pssLightCount(); vec4 pssLight(uint l);   // position, intensity
//   vec4 pssMaterial();   // diffuse, specular, shininess, transparency
//   float pssReflectivity();
//   vec4 pssIors();       // the indices of refraction of R, G and B; w: ambient
//   vec3 pssColor(uint point);                     // the point's color (linear)
//   vec3 pssBackground();
//   bool pssExact();      // the exact mode for camera and refracted rays (shadow rays: fast)
//   bool pssShadows();    // shadow rays
//   bool pssVolume();     // whether there is a volume inside (pss_volume.h, included before)

// The light reaching p (normal n facing the viewer, seen along -view) from the lights, Phong,
// each light's share cut by a shadow ray.
vec3 pssShade(vec3 p, vec3 n, vec3 view, vec3 base, float scale) {
  vec4 material = pssMaterial();
  vec3 c = pssIors().w * base;
  for (uint l = 0u; l < pssLightCount(); ++l) {
    vec4 light = pssLight(l);
    vec3 toLight = vec3(light) - p;
    float distance = length(toLight);
    toLight /= distance;
    float diffuse = dot(n, toLight);
    if (diffuse <= 0.0f) continue;
    float t = 0.0f;
    vec3 hitNormal = vec3(0.0f);
    uint point = 0u;
    if (pssShadows() && pssFirstHit(p, toLight, 1e-3f * scale, distance, t, hitNormal, point))
      continue;
    vec3 reflected = 2.0f * diffuse * n - toLight;
    float specular = pow(max(dot(reflected, -view), 0.0f), material.z);
    c += light.w * (material.x * diffuse * base + material.y * specular);
  }
  return c;
}

// The surface's first hit along o + t d (t > tMin) and the ray leaving it into the object or
// out of it by Snell's law for `ior` (inside-out when the normal faces along d; total internal
// reflection reflects). `inside`: the hit leaves the object.
bool pssRefraction(vec3 o, vec3 d, float ior, float tMin, ISO_INOUT(vec3) p, ISO_INOUT(vec3) n,
                   ISO_INOUT(vec3) bent, ISO_INOUT(uint) point) {
  float t = 0.0f;
  int projections = 0;
  if (!pssHit(o, d, tMin, 3.0e38f, pssExact(), t, n, point, projections)) return false;
  p = o + t * d;
  bool entering = dot(n, d) < 0.0f;  // normals face out of the object
  if (!entering) n = -n;             // n: against d
  vec3 r = refract(d, n, entering ? 1.0f / ior : ior);
  bent = dot(r, r) > 0.0f ? normalize(r) : reflect(d, n);
  return true;
}

const int kPssStack = 8;     // rays waiting at most (a path's reflections and refractions)
const int kPssMaxRays = 16;  // rays traced for one camera ray's channel at most

// The color the ray o + t d brings, in channel `channel` (0 to 2) with that channel's index of
// refraction, or in all three (channel 3) with the red one. At each surface: its own light
// (1 − reflectivity − transparency of it), a reflected ray (reflectivity) and a refracted one
// (transparency, through the volume inside when it enters), traced from a small stack, the
// refracted first; rays beyond kPssMaxRays or the stack are dropped (dark). `scale`: the scene's
// size (offsets).
vec3 pssTrace(vec3 o0, vec3 d0, int channel, float scale) {
  vec4 material = pssMaterial();
  float reflectivity = pssReflectivity();
  float ior = channel == 3 ? pssIors().x : pssIors()[channel];
  vec3 stackO[kPssStack], stackD[kPssStack];
  float stackWeight[kPssStack], stackMin[kPssStack];
  stackO[0] = o0;
  stackD[0] = d0;
  stackWeight[0] = 1.0f;
  stackMin[0] = 0.0f;
  int top = 1;
  vec3 color = vec3(0.0f);
  float offset = 1e-4f * scale;
  for (int ray = 0; ray < kPssMaxRays && top > 0; ++ray) {
    --top;
    vec3 o = stackO[top], d = stackD[top];
    float through = stackWeight[top], tMin = stackMin[top];
    vec3 p = vec3(0.0f), facing = vec3(0.0f), bent = vec3(0.0f);
    uint point = 0u;
    if (!pssRefraction(o, d, ior, tMin, p, facing, bent, point)) {
      color += through * pssBackground();
      continue;
    }
    float own = max(1.0f - material.w - reflectivity, 0.0f);
    if (own > 0.0f) color += through * own * pssShade(p, facing, d, pssColor(point), scale);
    if (reflectivity > 0.0f && top < kPssStack) {
      stackO[top] = p;
      stackD[top] = reflect(d, facing);
      stackWeight[top] = through * reflectivity;
      stackMin[top] = offset;
      ++top;
    }
    if (material.w > 0.0f && top < kPssStack) {
      float weight = through * material.w;
      // Into the object (the ray now runs against the outward normal): through its volume to
      // where it leaves.
      if (pssVolume() && dot(bent, facing) < 0.0f) {
        float t = 0.0f;
        vec3 n = vec3(0.0f);
        int projections = 0;
        uint other = 0u;
        if (pssHit(p, bent, offset, 3.0e38f, pssExact(), t, n, other, projections)) {
          float let = 1.0f;
          color += weight * pssIntegrate(p, bent, t, let);
          weight *= let;
        }
      }
      stackO[top] = p;
      stackD[top] = bent;
      stackWeight[top] = weight;
      stackMin[top] = offset;
      ++top;
    }
  }
  return color;
}

// The color of a camera ray: the three channels along their own paths when their indices of
// refraction differ on a transparent surface, else one path.
vec3 pssRayColor(vec3 o, vec3 d, float scale) {
  vec4 iors = pssIors();
  if (pssMaterial().w <= 0.0f || (iors.x == iors.y && iors.y == iors.z))
    return pssTrace(o, d, 3, scale);
  return vec3(pssTrace(o, d, 0, scale).x, pssTrace(o, d, 1, scale).y, pssTrace(o, d, 2, scale).z);
}
