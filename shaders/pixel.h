// A linear color as an sRGB8 RGBA word (alpha 255), as viewer::imagePixelWord on the CPU: the
// pictures of the compute shaders that write words (image.comp.glsl, pss.comp.glsl).
uint pixelWord(vec3 linear) {
  vec3 c = clamp(linear, 0.0f, 1.0f);
  uint word = 0xFF000000u;
  for (int k = 0; k < 3; ++k) {
    float s = c[k] <= 0.0031308f ? 12.92f * c[k] : 1.055f * pow(c[k], 1.0f / 2.4f) - 0.055f;
    word |= uint(round(s * 255.0f)) << (8 * k);
  }
  return word;
}
