// Image-space point rendering (Dobrev, Rosenthal and Linsen; specs/viewer.md "Image-space points"):
// the per-point and per-pixel steps, one source for the GPU and for the CPU reference
// (tracer/point_image.cpp), as trace.h is for the tracer.
//
// A layer is two images: each pixel's depth (distance to the viewpoint / far, in (0, 1]; 0 where
// no point is: "background") and the index of the point whose values it shows (kImageNoPoint
// for none). Points are projected into it by an atomic minimum of (depth bits << 32 | index)
// (the includer's), then its holes are filled, pass after pass, and only then is it shaded,
// smoothed and anti-aliased. A filled pixel takes its neighbour's depth and point, so shading a
// pixel is lighting its point: the paper lights points before projecting them, the same colors.
//
// The includer provides, before including this file:
//   ImageParams Q;                     the pass's parameters (shared.h)
//   vec3 pointPosition(uint i);        a point (world units from the scene's origin)
//   vec3 pointNormal(uint i);          its normal, unit, or zero when it has none
//   vec4 pointColor(uint i);           rgb: its linear color (its own or its object's); a: its
//                                      object's opacity
//   float pointSpacing(uint i);        the distance between neighbouring points around it
//   float pointShadow(uint i, uint light);  the fraction of the light that reaches it (shadow
//                                      texture; read when kImageShadows is set)
//   float layerDepth(ivec2 p);         the layer being filled or shaded, 0 outside the image
//   uint layerIndex(ivec2 p);          its points, kImageNoPoint outside the image
//   float referenceDepth(ivec2 p);     the previous layer, filled (kImagePeel)
//   vec4 layerColor(ivec2 p);          the shaded layer (premultiplied RGBA), 0 outside
// and the macro ISO_INOUT(T) (GLSL `inout T`, C++ `T&`).
//
// Float literals carry an `f` so that the C++ build does the same single-precision arithmetic.

// Where point p (normal n, zero for none) lands in the image and its depth, or false when it
// lies outside the view, before the near plane or faces away (kImageCull).
bool imageProject(vec3 p, vec3 n, ISO_INOUT(ivec2) pixel, ISO_INOUT(float) depth) {
  vec3 v = p - vec3(Q.eye);
  float z = dot(v, vec3(Q.forward));
  if (!(z > Q.forward.w)) return false;
  if ((Q.image.w & kImageCull) != 0u && dot(n, v) > 0.0f) return false;
  float x = (dot(v, vec3(Q.toX)) / z * 0.5f + 0.5f) * float(Q.image.x);
  float y = (0.5f - dot(v, vec3(Q.toY)) / z * 0.5f) * float(Q.image.y);
  if (!(x >= 0.0f && y >= 0.0f && x < float(Q.image.x) && y < float(Q.image.y))) return false;
  pixel = ivec2(int(x), int(y));
  depth = clamp(length(v) * Q.eye.w, 1.0e-7f, 1.0f);
  return true;
}

// Depth peeling: whether a point at `depth` on `pixel` belongs to a layer behind the previous
// one, that is lies farther than the previous layer's (filled) depth plus the layer gap d̃. Where
// the previous layer has no point, no point is left either.
bool imageBehindLast(ivec2 pixel, float depth) {
  if ((Q.image.w & kImagePeel) == 0u) return true;
  float last = referenceDepth(pixel);
  return last > 0.0f && depth > last + Q.layer.x;
}

// The radius (pixels) of the masks that decide whether a pixel next to point i (seen at `depth`)
// lies within the surface: the point spacing in pixels there, at least 1 (the paper's 3×3 masks)
// and at most image.z. Masks narrower than the spacing cannot tell a gap between points from the
// silhouette: both look like a pixel with background on one side.
int imageFillRadius(uint i, float depth) {
  float pixels = pointSpacing(i) / (depth / Q.eye.w * Q.layer.y);
  return clamp(int(ceil(pixels)), 1, int(Q.image.z));
}

// Whether a pixel of depth d counts as covering for the test of a pixel of depth `self`: any
// point for the background pass (self = 0), a point nearer by more than d̃ for the occluded pass.
bool imageCovers(float d, float self) {
  if (self == 0.0f) return d > 0.0f;
  return d > 0.0f && d < self - Q.layer.x;
}

// The masks (below) that a covering pixel at (dx, dy) from p lies in, as bits: 1 north (dy < 0),
// 2 south, 4 west (dx < 0), 8 east, 16 north-west, 32 north-east, 64 south-west, 128 south-east.
uint imageMaskBits(int dx, int dy) {
  uint bits = 0u;
  if (dy < 0) bits |= 1u;
  if (dy > 0) bits |= 2u;
  if (dx < 0) bits |= 4u;
  if (dx > 0) bits |= 8u;
  if (dx <= 0 && dy <= 0) bits |= 16u;
  if (dx >= 0 && dy <= 0) bits |= 32u;
  if (dx <= 0 && dy >= 0) bits |= 64u;
  if (dx >= 0 && dy >= 0) bits |= 128u;
  return bits;
}

// The rest of a filling pass at pixel p (imageFill) once its 3×3 neighbours are known: `self`
// its depth, `best` the least depth of its covering neighbours (≤ 1) and `point` that
// neighbour's point, `ring` the masks those neighbours fill. Whether p takes that neighbour's
// values (then depth and index are set to them).
bool imageFillBeyond(ivec2 p, int round, float self, float best, uint point, uint ring,
                     ISO_INOUT(float) depth, ISO_INOUT(uint) index) {
  int r = imageFillRadius(point, best);
  if (self > 0.0f && round >= r) return false;
  // Ring after ring outward (the pixels at distance k = 2 to r after the 3×3), so that a pixel
  // inside a hole, whose masks the nearest ring already fills, stops early; the bits do not
  // depend on the order.
  uint found = ring;
  for (int k = 2; k <= r && found != 255u; ++k) {
    // The ring's pixels: its top and bottom rows (2k + 1 each), then its sides between them.
    for (int i = 0; i < 8 * k; ++i) {
      int dx = 0, dy = 0;
      if (i < 2 * k + 1) {
        dx = i - k;
        dy = -k;
      } else if (i < 4 * k + 2) {
        dx = i - 3 * k - 1;
        dy = k;
      } else {
        int j = i - (4 * k + 2);
        dx = (j & 1) == 0 ? -k : k;
        dy = (j >> 1) - k + 1;
      }
      if (imageCovers(layerDepth(p + ivec2(dx, dy)), self)) found |= imageMaskBits(dx, dy);
    }
  }
  if (found != 255u) return false;
  depth = best;
  index = point;
  return true;
}

// One pass of hole filling at pixel p (the paper's sections 3.2 and 3.3, with masks of radius r):
// a background pixel (or, for the occluded pass, a pixel showing a layer behind the front one)
// with a covering 3×3 neighbour takes the values of its covering neighbour of least depth unless
// one of eight masks holds no covering pixel, which means p lies beyond the silhouette. The masks
// around p, of radius r: the four sides (r rows or columns, 2r + 1 long) and the four quadrants
// ((r + 1)², p's row and column included, p excluded). The paper's test, the product of the
// masks' depth sums being zero, is the same as one mask holding no covering pixel; here each
// mask's "holds one" is a bit. Returns whether the pixel changed; depth and index are its values.
// An occluded pixel is a candidate only in the first r passes (`round` counts from 0): a hole in
// a front layer whose points lie r pixels apart closes within them, and what later passes would
// still take is a crease deeper than d̃, flattened a pixel a pass.
bool imageFill(ivec2 p, int round, ISO_INOUT(float) depth, ISO_INOUT(uint) index) {
  float self = layerDepth(p);
  depth = self;
  index = layerIndex(p);
  float best = 2.0f;
  ivec2 from = p;
  uint ring = 0u;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      float d = layerDepth(p + ivec2(dx, dy));
      if ((dx == 0 && dy == 0) || !imageCovers(d, self)) continue;
      ring |= imageMaskBits(dx, dy);
      if (d < best) {
        best = d;
        from = p + ivec2(dx, dy);
      }
    }
  }
  if (best > 1.0f) return false;
  return imageFillBeyond(p, round, self, best, layerIndex(from), ring, depth, index);
}

// The color of point i lit by the pass's lights (Phong: ambient, diffuse, specular; the diffuse
// and specular parts of light l scaled by its shadow texture value), seen from the eye, as
// premultiplied RGBA with its object's opacity.
vec4 imageLight(uint i) {
  vec4 base = pointColor(i);
  vec3 p = pointPosition(i);
  vec3 n = pointNormal(i);
  vec3 c = vec3(Q.ambient) * vec3(base);
  if (dot(n, n) > 0.0f) {
    vec3 toEye = normalize(vec3(Q.eye) - p);
    if (dot(n, toEye) < 0.0f) n = -n;  // seen from behind (no culling): lit as its front
    uint lights = uint(Q.ambient.w);
    for (uint l = 0u; l < lights; ++l) {
      vec3 toLight = normalize(vec3(Q.lights[l].position) - p);
      float diffuse = dot(n, toLight);
      if (diffuse <= 0.0f) continue;
      vec3 reflected = 2.0f * diffuse * n - toLight;
      float specular = pow(max(dot(reflected, toEye), 0.0f), Q.material.z);
      float m = (Q.image.w & kImageShadows) != 0u ? pointShadow(i, l) : 1.0f;
      c += m * vec3(Q.lights[l].color) * (Q.material.x * diffuse * vec3(base) + Q.material.y * specular);
    }
  } else {
    c = vec3(base);  // no normal: unlit
  }
  return vec4(c * base.a, base.a);
}

// Normal-free shading from the filled depth alone (eye-dome style): how far the pixel lies behind
// its neighbours two pixels away, on a log scale, darkens it.
float imageEyeDome(ivec2 p) {
  float d = layerDepth(p);
  if (d <= 0.0f) return 1.0f;
  float response = 0.0f;
  for (int k = 0; k < 4; ++k) {
    ivec2 step = k < 2 ? ivec2(k == 0 ? 2 : -2, 0) : ivec2(0, k == 2 ? 2 : -2);
    float q = layerDepth(p + step);
    if (q > 0.0f) response += max(0.0f, log2(d) - log2(q));
  }
  return exp(-Q.layer.w * response);
}

// The shaded pixel (premultiplied RGBA; 0 for background).
vec4 imageShade(ivec2 p) {
  uint i = layerIndex(p);
  if (i == kImageNoPoint) return vec4(0.0f);
  if ((Q.image.w & kImageEyeDome) == 0u) return imageLight(i);
  vec4 base = pointColor(i);  // eye-dome shading: the point's own color, darkened
  return vec4(vec3(base) * (base.a * imageEyeDome(p)), base.a);
}

// Smoothing (section 3.4): the "alleviated" Gaussian (1 2 1, 2 16 2, 1 2 1 over 28) over the
// covered pixels of the 3×3 neighbourhood, renormalised; background stays background.
vec4 imageSmooth(ivec2 p) {
  if (layerDepth(p) <= 0.0f || (Q.image.w & kImageSmoothOff) != 0u) return layerColor(p);
  vec4 sum = vec4(0.0f);
  float weights = 0.0f;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      ivec2 q = p + ivec2(dx, dy);
      if (layerDepth(q) <= 0.0f) continue;
      float w = dx == 0 && dy == 0 ? 16.0f : (dx == 0 || dy == 0 ? 2.0f : 1.0f);
      sum += w * layerColor(q);
      weights += w;
    }
  }
  return sum / weights;
}

// Anti-aliasing (section 3.5): where the Laplace filter of the depth marks an edge, the pixel
// takes the mean of its 3×3 neighbourhood (premultiplied: background counts as transparent).
// Edges: silhouettes (the pixel and its four neighbours are not all covered or all background),
// and with kImageAaEdges also where |Laplace| exceeds d̃ (the edge of a nearer layer).
vec4 imageAntialias(ivec2 p) {
  vec4 own = layerColor(p);
  if ((Q.image.w & kImageAaOff) != 0u) return own;
  float d = layerDepth(p);
  float n0 = layerDepth(p + ivec2(1, 0));
  float n1 = layerDepth(p + ivec2(-1, 0));
  float n2 = layerDepth(p + ivec2(0, 1));
  float n3 = layerDepth(p + ivec2(0, -1));
  int covered = (d > 0.0f ? 1 : 0) + (n0 > 0.0f ? 1 : 0) + (n1 > 0.0f ? 1 : 0) +
                (n2 > 0.0f ? 1 : 0) + (n3 > 0.0f ? 1 : 0);
  bool edge = covered != 0 && covered != 5;
  if (!edge && covered == 5 && (Q.image.w & kImageAaEdges) != 0u)
    edge = abs(4.0f * d - n0 - n1 - n2 - n3) > Q.layer.x;
  if (!edge) return own;
  vec4 sum = vec4(0.0f);
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) sum += layerColor(p + ivec2(dx, dy));
  return sum / 9.0f;
}

// Shadow textures (section 6), for a pass whose viewpoint is a light (or a sample of an area
// light) and whose layer is the light's first layer, filled for occluded pixels: whether the
// point (position p, normal n) belongs to that layer, that is lies within Δd = d̃ / |cos| of its
// depth, the angle taken between the light's ray and the normal (truncated at layer.z). Points
// outside the light's view, or that face away from it, are not lit.
bool imageLit(vec3 p, vec3 n) {
  ivec2 pixel = ivec2(0);
  float depth = 0.0f;
  if (!imageProject(p, n, pixel, depth)) return false;
  float reference = layerDepth(pixel);
  if (reference <= 0.0f) return true;
  float cosine = 1.0f;
  if (dot(n, n) > 0.0f) cosine = max(abs(dot(normalize(p - vec3(Q.eye)), n)), Q.layer.z);
  return depth <= reference + Q.layer.x / cosine;
}
