// Volumes from scattered data (seed 001, its equation 3; specs/viewer.md, "Point set surfaces"):
// the value at a point is the Gaussian-weighted mean of the values of the scattered points near
// it, a transfer function maps it to an emitted color and an extinction, and a ray's segment
// through the volume is integrated by emission and absorption. Read by the point set surfaces'
// tracer (pss_trace.h) and by the viewer's tracer (trace.h) inside transparent objects. Compiled
// as GLSL and as C++; the includer provides:
//   bool pssVolume();            // whether there is one
//   vec4 pssVolumeSettings();    // smoothing r, reach (points farther do not count), step, 0
//   vec3 pssVolumeLo(); float pssVolumeSide(); ivec3 pssVolumeDims();  // its grid
//   uint pssVolumeStart(uint cell); uint pssVolumeAt(uint k);          // a cell's points
//   vec4 pssVolumePoint(uint i);                                       // position, value
//   uint pssTransferCount();     // the transfer function's control points, by value
//   vec4 pssTransfer(uint k);    // (value, extinction per unit length, 0, 0)
//   vec4 pssTransferColor(uint k);  // emitted color (linear)

// The scattered data's value at x: the Gaussian-weighted mean of the values of the points within
// reach (the paper's equation 3, smoothing r); negative where none is.
float pssVolumeValue(vec3 x) {
  vec4 settings = pssVolumeSettings();
  float reach = settings.y, inv = 0.5f / (settings.x * settings.x);
  ivec3 dims = pssVolumeDims();
  ivec3 a = clamp(ivec3(floor((x - reach - pssVolumeLo()) / pssVolumeSide())), ivec3(0), dims - 1);
  ivec3 b = clamp(ivec3(floor((x + reach - pssVolumeLo()) / pssVolumeSide())), ivec3(0), dims - 1);
  float sum = 0.0f, weights = 0.0f;
  for (int cz = a.z; cz <= b.z; ++cz)
    for (int cy = a.y; cy <= b.y; ++cy)
      for (int cx = a.x; cx <= b.x; ++cx) {
        uint c = (uint(cz) * uint(dims.y) + uint(cy)) * uint(dims.x) + uint(cx);
        uint end = pssVolumeStart(c + 1u);
        for (uint k = pssVolumeStart(c); k < end; ++k) {
          vec4 p = pssVolumePoint(pssVolumeAt(k));
          vec3 r = vec3(p) - x;
          float d = dot(r, r);
          if (d > reach * reach) continue;
          float w = exp(-d * inv);
          sum += w * p.w;
          weights += w;
        }
      }
  return weights > 0.0f ? sum / weights : -1.0f;
}

// The transfer function at a value: (emitted color, extinction), linear between its control
// points, a value beyond them taking the nearer end's.
vec4 pssTransferAt(float value) {
  uint count = pssTransferCount();
  vec4 first = pssTransfer(0u);
  if (value <= first.x) return vec4(vec3(pssTransferColor(0u)), first.y);
  for (uint k = 1u; k < count; ++k) {
    vec4 right = pssTransfer(k);
    if (value <= right.x) {
      vec4 left = pssTransfer(k - 1u);
      float f = right.x > left.x ? (value - left.x) / (right.x - left.x) : 1.0f;
      return vec4(mix(vec3(pssTransferColor(k - 1u)), vec3(pssTransferColor(k)), f),
                  mix(left.y, right.y, f));
    }
  }
  return vec4(vec3(pssTransferColor(count - 1u)), pssTransfer(count - 1u).y);
}

// Emission and absorption along o + t d for t in [0, span] (midpoint samples about the step
// apart): the light emitted towards o, and what is let through (transmittance) in `through`.
vec3 pssIntegrate(vec3 o, vec3 d, float span, ISO_INOUT(float) through) {
  float step = pssVolumeSettings().z;
  int n = max(int(ceil(span / step)), 1);
  float dt = span / float(n);
  vec3 color = vec3(0.0f);
  float transmittance = 1.0f;
  for (int i = 0; i < n; ++i) {
    float value = pssVolumeValue(o + (float(i) + 0.5f) * dt * d);
    if (value < 0.0f) continue;  // no data here: empty
    vec4 tf = pssTransferAt(value);
    float a = exp(-tf.w * dt);
    color += transmittance * (1.0f - a) * vec3(tf);
    transmittance *= a;
  }
  through = transmittance;
  return color;
}
