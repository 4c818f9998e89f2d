// Shading: background and environment, lights and shadows, reflections and refractions, and
// one pixel's color. Part of the tracer (trace.h).

uint hashUint(uint x) {
  x ^= x >> 16u;
  x *= 0x7feb352du;
  x ^= x >> 15u;
  x *= 0x846ca68bu;
  x ^= x >> 16u;
  return x;
}

float randomUnit(ISO_INOUT(uint) state) {
  state = hashUint(state + 0x9e3779b9u);
  return float(state >> 8u) * (1.0f / 16777216.0f);
}

vec3 background(vec3 d) {
  vec3 up = vec3(P.worldUp.x, P.worldUp.y, P.worldUp.z);
  float h = dot(d, up);
  if ((P.options.x & kOptionEnvironment) != 0u) {
    // Equirectangular: longitude around `up`, latitude from it; bilinear filtering.
    vec3 a = abs(up.x) < 0.9f ? vec3(1.0f, 0.0f, 0.0f) : vec3(0.0f, 1.0f, 0.0f);
    vec3 e1 = normalize(cross(up, a));
    vec3 e2 = cross(up, e1);
    float phi = atan(dot(d, e2), dot(d, e1));
    float theta = acos(clamp(h, -1.0f, 1.0f));
    float w = float(P.pool.z), hgt = float(P.pool.w);
    float x = (phi * 0.15915494f + 0.5f) * w - 0.5f;
    float y = theta * 0.31830989f * hgt - 0.5f;
    float fx = floor(x), fy = floor(y);
    float ax = x - fx, ay = y - fy;
    uint x0 = uint(int(fx) < 0 ? int(fx) + int(P.pool.z) : int(fx)) % P.pool.z;
    uint x1 = (x0 + 1u) % P.pool.z;
    uint y0 = uint(clamp(int(fy), 0, int(P.pool.w) - 1));
    uint y1 = uint(clamp(int(fy) + 1, 0, int(P.pool.w) - 1));
    vec3 top = mix(environmentTexel(x0, y0), environmentTexel(x1, y0), ax);
    vec3 bottom = mix(environmentTexel(x0, y1), environmentTexel(x1, y1), ax);
    return P.lod.z * mix(top, bottom, ay);
  }
  vec3 top = vec3(P.skyTop.x, P.skyTop.y, P.skyTop.z);
  vec3 bottom = vec3(P.skyBottom.x, P.skyBottom.y, P.skyBottom.z);
  return mix(bottom, top, clamp(0.5f + 0.5f * h, 0.0f, 1.0f));
}

// Where a point p of the ground lies on the caustic map, in cells (cell (i, j) spans [i, i + 1) ×
// [j, j + 1)).
vec2 causticCell(vec3 p) {
  return vec2(dot(vec3(P.causticU.x, P.causticU.y, P.causticU.z), p) + P.causticU.w,
              dot(vec3(P.causticV.x, P.causticV.y, P.causticV.z), p) + P.causticV.w);
}

// The irradiance the caustic map adds at a point p of the ground (caustics.h): its cells
// interpolated bilinearly between their centers, none outside the map.
vec3 causticIrradiance(vec3 p) {
  vec2 at = causticCell(p) - vec2(0.5f);
  float last = float(kCausticCells);
  float x = clamp(at.x, -2.0f, last);
  float y = clamp(at.y, -2.0f, last);
  float fx = floor(x), fy = floor(y);
  vec3 sum = vec3(0.0f);
  for (uint k = 0u; k < 4u; ++k) {
    int i = int(fx) + int(k & 1u);
    int j = int(fy) + int(k >> 1u);
    if (i < 0 || j < 0 || i >= int(kCausticCells) || j >= int(kCausticCells)) continue;
    float w = ((k & 1u) != 0u ? x - fx : 1.0f - (x - fx)) *
              ((k & 2u) != 0u ? y - fy : 1.0f - (y - fy));
    uint at = 3u * (uint(j) * kCausticCells + uint(i));
    sum += w * vec3(float(causticWord(at)), float(causticWord(at + 1u)),
                    float(causticWord(at + 2u)));
  }
  return sum * (1.0f / kCausticScale);
}

// Phong lighting at p with the shading normal hit.normal (facing the ray) seen from direction
// -d, with shadow rays that leave the surface on the side `from` of the hit.
// `rays` counts the rays traced by kind: x camera, y shadow, z reflected and refracted.
vec3 shade(vec3 p, vec3 d, Hit hit, float distance, ISO_INOUT(uint) rng, ISO_INOUT(uvec3) rays) {
  vec3 n = hit.normal;
  vec3 ambient = vec3(P.ambient.x, P.ambient.y, P.ambient.z);
  vec3 color = ambient * hit.occlusion * hit.color;
  vec3 origin = p + n * P.lod.y;
  // Baked lighting (--lighting baked or both): the irradiance of the hit's surface lights its
  // diffuse term. Back faces and hits without it (splats, the ground) keep live lighting.
  bool baked = (P.options.x & kOptionBakedLight) != 0u && hit.irradiance.w > 0.0f &&
               hit.from > 0.0f;
  bool live = !baked || (P.options.x & kOptionLiveLight) != 0u;
  if (baked) color += P.material.x * hit.color * vec3(hit.irradiance.x, hit.irradiance.y,
                                                      hit.irradiance.z);
  for (uint i = 0u; i < kMaxLights; ++i) {
    Light light = P.lights[i];
    uint kind = uint(light.position.w);
    uint samples = kind == kLightArea ? max(uint(light.color.w), 1u) : 1u;
    if (kind == kLightNone) samples = 0u;
    vec3 sum = vec3(0.0f);
    for (uint s = 0u; s < samples; ++s) {
      vec3 at = vec3(light.position.x, light.position.y, light.position.z);
      if (kind == kLightArea) {
        // Stratified over a near-square grid of cells, jittered per pixel.
        uint columns = uint(ceil(sqrt(float(samples))));
        uint rows = (samples + columns - 1u) / columns;
        float a = (float(s % columns) + randomUnit(rng)) / float(columns) - 0.5f;
        float b = (float(s / columns) + randomUnit(rng)) / float(rows) - 0.5f;
        at += a * vec3(light.u.x, light.u.y, light.u.z) + b * vec3(light.v.x, light.v.y, light.v.z);
      }
      vec3 l = at - p;
      float lengthL = length(l);
      l = l / lengthL;
      float falloff = light.u.w > 0.0f ? 1.0f / (lengthL * lengthL) : 1.0f;
      float lambert = dot(n, l);
      bool lit = lambert > 0.0f;
      if (lit && live && (P.options.x & kOptionShadows) != 0u) {
        Hit blocker;
        rays.y += 1u;
        lit = !traceScene(origin, l, P.lod.w, lengthL, hit.from, false, distance, false, blocker);
      }
      if (lit) {
        // Baked alone: the specular highlight stays live (without a shadow ray), the diffuse
        // term is the baked one.
        vec3 r = reflect(-l, n);
        float specular = pow(max(dot(r, -d), 0.0f), P.albedo.w);
        vec3 diffuse = live ? P.material.x * lambert * hit.color : vec3(0.0f);
        sum += falloff * (diffuse + vec3(P.material.y * specular));
      }
    }
    if (samples > 0u)
      color += vec3(light.color.x, light.color.y, light.color.z) * sum / float(samples);
  }
  // The caustics on the ground: light that came there through specular bounces.
  if (P.caustics.x > 0u && onGround(hit))
    color += P.material.x * hit.color * causticIrradiance(p);
  return color;
}

// shade() at a hit outside transparent objects, whose normal already faces the ray: back faces
// seen from behind (hit.from < 0) take the back-face tint when it is on.
vec3 shadeOutside(vec3 p, vec3 d, Hit hit, float distance, ISO_INOUT(uint) rng,
                  ISO_INOUT(uvec3) rays) {
  if (hit.from < 0.0f && (P.options.x & kOptionBackTint) != 0u)
    hit.color *= vec3(P.backface.x, P.backface.y, P.backface.z);
  return shade(p, d, hit, distance, rng, rays);
}

// The material's reflectivity and transparency at a hit, when those rays are on (the ground is
// diffuse: none).
float hitReflectivity(Hit hit) {
  return (P.options.x & kOptionReflections) != 0u && !onGround(hit) ? P.material.z : 0.0f;
}
float hitTransparency(Hit hit) {
  return (P.options.x & kOptionRefractions) != 0u && !onGround(hit) ? P.material.w : 0.0f;
}

// The part of a hit's color shaded locally: the rest is reflected and refracted.
float localFraction(Hit hit) { return 1.0f - hitReflectivity(hit) - hitTransparency(hit); }

// A pending ray's side of the surface (-1, 0, +1) and whether it travels inside a transparent
// object, packed into one float of the ray stack.
float packRayState(float side, bool inMedium) { return side + 1.0f + (inMedium ? 4.0f : 0.0f); }

// The color seen along a camera ray, with reflection and refraction rays up to the bounce limit.
// Camera rays see both sides of the surface: a back face (crossed from f < 0) is shaded with the
// flipped normal, tinted (kOptionBackTint) or passed through (kOptionBackHide). Every hit is shaded
// with the normal facing the ray; the rays that leave it keep the side they leave on.
// Pending rays wait on a small stack of vec4s: origin and path length before it, direction and
// bounce count, weight and the ray's state (packRayState). The camera ray starts at `start`
// (its tile's, cone.h: empty space before it).
vec3 radiance(vec3 o, vec3 d, float start, ISO_INOUT(uint) rng, ISO_INOUT(uvec3) rays) {
  vec4 stackOrigin[kRayStack];
  vec4 stackDirection[kRayStack];
  vec4 stackWeight[kRayStack];
  bool hideBack = (P.options.x & kOptionBackHide) != 0u;
  // The camera ray first.
  vec3 origin = o;
  vec3 direction = d;
  vec3 weight = vec3(1.0f);
  float before = 0.0f;  // path length before origin
  uint depth = 0u;
  float side = hideBack ? 1.0f : 0.0f;
  bool inMedium = false;
  uint count = 0u;
  vec3 color = vec3(0.0f);
  float eta = P.medium.x;
  float offset = P.lod.y;
  bool more = true;  // a ray to trace
  while (more) {
    Hit hit;
    bool primary = depth == 0u;
    if (primary)
      rays.x += 1u;
    else
      rays.z += 1u;
    if (!traceScene(origin, direction, primary ? start : 0.0f, 1e30f, side, primary && hideBack,
                   before, primary && (P.options.x & kOptionRequests) != 0u, hit)) {
      color += weight * background(direction);
    } else {
      vec3 p = origin + direction * hit.t;
      vec3 n = hit.from * hit.normal;  // facing the ray
      hit.normal = n;
      float distance = before + hit.t;
      bool bounce = depth < P.options.y;
      if (!inMedium) {
        // Local shading, then the transmitted and the mirror rays.
        color += weight * localFraction(hit) *
                 shadeOutside(p, direction, hit, distance, rng, rays);
        float mirror = hitReflectivity(hit);
        float transparency = hitTransparency(hit);
        if (bounce && transparency > 0.0f) {
          vec3 r = refract(direction, n, 1.0f / eta);
          if (dot(r, r) > 0.0f && count < kRayStack) {
            stackOrigin[count] = vec4(p - n * offset, distance);
            stackDirection[count] = vec4(normalize(r), float(depth + 1u));
            stackWeight[count] = vec4(weight * transparency, packRayState(-hit.from, true));
            count += 1u;
          } else {
            mirror += transparency;
          }
        }
        if (bounce && mirror > 0.0f && count < kRayStack) {
          stackOrigin[count] = vec4(p + n * offset, distance);
          stackDirection[count] = vec4(reflect(direction, n), float(depth + 1u));
          stackWeight[count] = vec4(weight * mirror, packRayState(hit.from, false));
          count += 1u;
        }
      } else {
        // Inside a transparent object: a volume of scattered data there (pss_volume.h) emits and
        // absorbs along the way.
        if (pssCompiled() && (P.options.x & kOptionPss) != 0u && pssVolume()) {
          float through = 1.0f;
          color += weight * pssIntegrate(origin, direction, hit.t, through);
          weight *= through;
        }
      }
      if (inMedium && bounce && count < kRayStack) {
        // Leaving a transparent object: absorption along the way, then out or totally reflected.
        vec3 absorption = vec3(P.medium.y, P.medium.z, P.medium.w);
        vec3 r = refract(direction, n, eta);
        bool leaves = dot(r, r) > 0.0f;
        stackOrigin[count] = vec4(leaves ? p - n * offset : p + n * offset, distance);
        stackDirection[count] =
            vec4(leaves ? normalize(r) : reflect(direction, n), float(depth + 1u));
        stackWeight[count] =
            vec4(weight * exp(-absorption * hit.t),
                 leaves ? packRayState(-hit.from, false) : packRayState(hit.from, true));
        count += 1u;
      }
    }
    more = count > 0u;
    if (more) {
      count -= 1u;
      origin = vec3(stackOrigin[count].x, stackOrigin[count].y, stackOrigin[count].z);
      before = stackOrigin[count].w;
      direction = vec3(stackDirection[count].x, stackDirection[count].y, stackDirection[count].z);
      depth = uint(stackDirection[count].w);
      weight = vec3(stackWeight[count].x, stackWeight[count].y, stackWeight[count].z);
      uint state = uint(stackWeight[count].w + 0.5f);
      side = float(state & 3u) - 1.0f;
      inMedium = state >= 4u;
    }
  }
  return color;
}

// The 8-bit sRGB code of a linear value, clamped to [0, 1]: how many of the bounds where the code
// rises it reaches (FrameParams.srgbBounds), by a binary search of 8 steps.
uint srgbCode(float c) {
  uint code = 0u;
  for (uint step = 128u; step > 0u; step >>= 1u) {
    uint k = code + step - 1u;
    if (c >= P.srgbBounds[k >> 2u][k & 3u]) code += step;
  }
  return code;
}

// The direction of the camera ray through pixel (x, y) at offset (jx, jy) in it.
vec3 cameraDirection(uint x, uint y, float jx, float jy) {
  vec3 right = vec3(P.right.x, P.right.y, P.right.z);
  vec3 up = vec3(P.up.x, P.up.y, P.up.z);
  vec3 forward = vec3(P.forward.x, P.forward.y, P.forward.z);
  float sx = 2.0f * (float(x) + jx) / float(P.image.x) - 1.0f;
  float sy = 1.0f - 2.0f * (float(y) + jy) / float(P.image.y);
  return normalize(forward + sx * right + sy * up);
}

// The pixel's random state at the start of its samples.
uint pixelSeed(uint x, uint y) { return hashUint(x * 1973u + y * 9277u + P.image.w * 26699u); }

// A linear color as the packed 8-bit sRGB pixel (BGRA with kOptionSwapRB).
uint packPixel(vec3 c) {
  uint r = srgbCode(c.x);
  uint gc = srgbCode(c.y);
  uint b = srgbCode(c.z);
  if ((P.options.x & kOptionSwapRB) != 0u) {
    uint swap = r;
    r = b;
    b = swap;
  }
  return r | (gc << 8u) | (b << 16u) | (255u << 24u);
}

// The packed 8-bit color of pixel (x, y): the mean of P.image.z jittered samples, whose camera
// rays start at `start`.
uint renderPixel(uint x, uint y, float start, ISO_INOUT(uvec3) rays) {
  uint samples = max(P.image.z, 1u);
  uint rng = pixelSeed(x, y);
  vec3 sum = vec3(0.0f);
  vec3 eye = vec3(P.eye.x, P.eye.y, P.eye.z);
  for (uint s = 0u; s < samples; ++s) {
    float jx = samples > 1u ? randomUnit(rng) : 0.5f;
    float jy = samples > 1u ? randomUnit(rng) : 0.5f;
    sum += radiance(eye, cameraDirection(x, y, jx, jy), start, rng, rays);
  }
  return packPixel(sum / float(samples));
}
