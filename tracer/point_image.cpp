// The CPU reference of image-space point rendering (point_image.h): shaders/image.h inside a C++
// class, its steps run over every point and pixel with TBB.
#include "tracer/point_image.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <glm/glm.hpp>

#include "iso/check.h"
#include "iso/error.h"
#include "shaders/shared.h"

namespace iso::viewer {
namespace image_shader {

using namespace glm;
using namespace iso::gpu;
#define ISO_INOUT(T) T&

// A layer: each pixel's depth (0: background) and point (kImageNoPoint: none).
struct Layer {
  std::vector<float> depth;
  std::vector<uint32_t> index;
};

// The GLSL environment of image.h: the points, the layer being worked on, the previous layer and
// the shaded colors, read from host memory.
class Pass {
 public:
  Pass(const ImageParams& params, const PointImageScene& scene, const float* shadow, uint lights)
      : Q(params),
        positions_(scene.positions().data()),
        normals_(scene.normals().data()),
        colors_(scene.colors().data()),
        shadow_(shadow),
        lights_(lights),
        width_(int(params.image.x)),
        height_(int(params.image.y)) {}

  ImageParams Q;
  const Layer* layer = nullptr;
  const Layer* reference = nullptr;
  const vec4* color = nullptr;

  vec3 pointPosition(uint i) const { return vec3(positions_[i]); }
  vec3 pointNormal(uint i) const { return vec3(normals_[i]); }
  vec4 pointColor(uint i) const { return colors_[i]; }
  float pointSpacing(uint i) const { return positions_[i].w; }
  float pointShadow(uint i, uint light) const { return shadow_[size_t(i) * lights_ + light]; }
  bool inside(ivec2 p) const { return p.x >= 0 && p.y >= 0 && p.x < width_ && p.y < height_; }
  size_t at(ivec2 p) const { return size_t(p.y) * size_t(width_) + size_t(p.x); }
  float layerDepth(ivec2 p) const { return inside(p) ? layer->depth[at(p)] : 0.0f; }
  uint layerIndex(ivec2 p) const { return inside(p) ? layer->index[at(p)] : kImageNoPoint; }
  float referenceDepth(ivec2 p) const { return inside(p) ? reference->depth[at(p)] : 0.0f; }
  vec4 layerColor(ivec2 p) const { return inside(p) ? color[at(p)] : vec4(0.0f); }

#include "shaders/image.h"

 private:
  const vec4* positions_;
  const vec4* normals_;
  const vec4* colors_;
  const float* shadow_;
  uint lights_;
  int width_, height_;
};

#undef ISO_INOUT

}  // namespace image_shader

namespace {

using image_shader::Layer;
using image_shader::Pass;
using gpu::ImageParams;
using gpu::kImageNoPoint;

// The parameters of a pass seen from `eye` toward `forward` with this field of view (radians,
// vertical), over a scene inside the box [lo, hi].
ImageParams viewParams(glm::vec3 eye, glm::vec3 forward, glm::vec3 up, float fov, int width,
                       int height, glm::vec3 lo, glm::vec3 hi) {
  forward = glm::normalize(forward);
  glm::vec3 right = glm::cross(forward, up);
  if (glm::dot(right, right) < 1e-12f) right = glm::cross(forward, glm::vec3(1, 0, 0));
  if (glm::dot(right, right) < 1e-12f) right = glm::cross(forward, glm::vec3(0, 1, 0));
  right = glm::normalize(right);
  const glm::vec3 upv = glm::cross(right, forward);
  const float t = std::tan(0.5f * fov);
  const float aspect = float(width) / float(height);
  float far = 0.0f;
  for (int c = 0; c < 8; ++c) {
    const glm::vec3 corner((c & 1) ? hi.x : lo.x, (c & 2) ? hi.y : lo.y, (c & 4) ? hi.z : lo.z);
    far = std::max(far, glm::length(corner - eye));
  }
  far = std::max(far * 1.001f, 1e-6f);
  ImageParams q{};
  q.eye = glm::vec4(eye, 1.0f / far);
  q.toX = glm::vec4(right / (t * aspect), 0.0f);
  q.toY = glm::vec4(upv / t, 0.0f);
  q.forward = glm::vec4(forward, far * 1e-6f);
  q.image = glm::uvec4(uint32_t(width), uint32_t(height), 1u, 0u);
  q.layer = glm::vec4(0.0f, 2.0f * t / float(height), kShadowLeastCosine, 0.0f);
  return q;
}

// Projects every point that passes `keep` into a fresh layer: per pixel the least
// (depth bits << 32 | index), as the GPU's 64-bit atomic minimum does.
template <typename Keep>
Layer project(Pass& pass, size_t points, Keep keep) {
  const size_t pixels = size_t(pass.Q.image.x) * pass.Q.image.y;
  std::vector<uint64_t> keys(pixels, ~uint64_t(0));
  tbb::parallel_for(tbb::blocked_range<size_t>(0, points, 1 << 14), [&](const auto& range) {
    for (size_t i = range.begin(); i != range.end(); ++i) {
      glm::ivec2 pixel(0);
      float depth = 0.0f;
      if (!pass.imageProject(pass.pointPosition(uint32_t(i)), pass.pointNormal(uint32_t(i)), pixel,
                             depth) ||
          !keep(uint32_t(i), pixel, depth))
        continue;
      const uint64_t key = uint64_t(std::bit_cast<uint32_t>(depth)) << 32 | uint64_t(i);
      std::atomic_ref<uint64_t> slot(keys[pass.at(pixel)]);
      uint64_t old = slot.load(std::memory_order_relaxed);
      while (key < old && !slot.compare_exchange_weak(old, key, std::memory_order_relaxed)) {
      }
    }
  });
  Layer layer{std::vector<float>(pixels), std::vector<uint32_t>(pixels)};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pixels), [&](const auto& range) {
    for (size_t k = range.begin(); k != range.end(); ++k) {
      const uint64_t key = keys[k];
      layer.depth[k] = key == ~uint64_t(0) ? 0.0f : std::bit_cast<float>(uint32_t(key >> 32));
      layer.index[k] = key == ~uint64_t(0) ? kImageNoPoint : uint32_t(key);
    }
  });
  return layer;
}

// Fills the holes of `layer`: background passes until none changes a pixel (unless
// `occludedOnly`), then occluded passes likewise. Returns the passes that changed something, of
// each kind.
std::pair<int, int> fill(Pass& pass, Layer& layer, int maxPasses, int maxOccluded,
                         bool occludedOnly = false) {
  const int width = int(pass.Q.image.x), height = int(pass.Q.image.y);
  Layer next = layer;
  int counts[2] = {0, 0};
  for (int kind = occludedOnly ? 1 : 0; kind < 2; ++kind) {
    for (int round = 0; round < (kind == 0 ? maxPasses : maxOccluded); ++round) {
      pass.layer = &layer;
      const size_t changed = tbb::parallel_reduce(
          tbb::blocked_range<int>(0, height), size_t(0),
          [&](const auto& rows, size_t sum) {
            for (int y = rows.begin(); y != rows.end(); ++y) {
              for (int x = 0; x < width; ++x) {
                const glm::ivec2 p(x, y);
                const size_t k = pass.at(p);
                const float self = layer.depth[k];
                float depth = self;
                uint32_t index = layer.index[k];
                // The background pass looks at background pixels, the occluded one at the others.
                if ((kind == 0) == (self == 0.0f) && pass.imageFill(p, round, depth, index)) ++sum;
                next.depth[k] = depth;
                next.index[k] = index;
              }
            }
            return sum;
          },
          std::plus<>());
      if (changed == 0) break;
      std::swap(layer, next);
      ++counts[kind];
    }
  }
  return {counts[0], counts[1]};
}

// Shades, smooths and anti-aliases a filled layer into premultiplied RGBA.
std::vector<glm::vec4> shade(Pass& pass, const Layer& layer) {
  const int width = int(pass.Q.image.x), height = int(pass.Q.image.y);
  const size_t pixels = size_t(width) * height;
  std::vector<glm::vec4> a(pixels), b(pixels);
  pass.layer = &layer;
  auto each = [&](auto&& f) {
    tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const auto& rows) {
      for (int y = rows.begin(); y != rows.end(); ++y)
        for (int x = 0; x < width; ++x) f(glm::ivec2(x, y));
    });
  };
  each([&](glm::ivec2 p) { a[pass.at(p)] = pass.imageShade(p); });
  pass.color = a.data();
  each([&](glm::ivec2 p) { b[pass.at(p)] = pass.imageSmooth(p); });
  pass.color = b.data();
  each([&](glm::ivec2 p) { a[pass.at(p)] = pass.imageAntialias(p); });
  pass.color = nullptr;
  return a;
}

// The i-th point of the Halton sequence in bases 2 and 3, in [0, 1)².
glm::vec2 halton(uint32_t i) {
  glm::vec2 r(0.0f);
  for (int axis = 0; axis < 2; ++axis) {
    const uint32_t base = axis == 0 ? 2u : 3u;
    float f = 1.0f, value = 0.0f;
    for (uint32_t n = i; n > 0; n /= base) {
      f /= float(base);
      value += f * float(n % base);
    }
    r[axis] = value;
  }
  return r;
}

}  // namespace

PointImageScene::PointImageScene(std::span<const ImageObject> objects) {
  size_t total = 0;
  for (const ImageObject& o : objects) total += o.positions.size();
  if (total >= kImageNoPoint) throw UsageError("image-space points: more than 2^32 - 1 points");
  positions_.reserve(total);
  normals_.reserve(total);
  colors_.reserve(total);
  lo_ = glm::vec3(std::numeric_limits<float>::max());
  hi_ = -lo_;
  bool anyNormals = false;
  for (const ImageObject& o : objects) {
    ISO_CHECK(o.normals.empty() || o.normals.size() == o.positions.size());
    ISO_CHECK(o.colors.empty() || o.colors.size() == o.positions.size());
    if (!(o.spacing > 0.0f)) throw UsageError("image-space points: an object without a spacing");
    anyNormals |= !o.normals.empty();
    ISO_CHECK(o.spacings.empty() || o.spacings.size() == o.positions.size());
    normalsAll_ &= !o.normals.empty() || o.positions.empty();
    orientedAll_ &= o.orientedNormals || o.positions.empty();
    largestSpacing_ = std::max(largestSpacing_, o.spacing);
    for (size_t i = 0; i < o.positions.size(); ++i) {
      positions_.emplace_back(o.positions[i], o.spacings.empty() ? o.spacing : o.spacings[i]);
      normals_.emplace_back(o.normals.empty() ? glm::vec3(0.0f) : o.normals[i], 0.0f);
      colors_.emplace_back(o.colors.empty() ? o.color : o.colors[i], o.opacity);
      lo_ = glm::min(lo_, o.positions[i]);
      hi_ = glm::max(hi_, o.positions[i]);
    }
  }
  normalsAll_ = normalsAll_ && anyNormals;
  orientedAll_ = orientedAll_ && normalsAll_;
  if (total == 0) lo_ = hi_ = glm::vec3(0.0f);
}

float PointImageScene::gap(const ImageSettings& settings) const {
  return settings.layerGap > 0.0f ? settings.layerGap : kDefaultGapSpacings * largestSpacing_;
}

ImagePlan planImage(const PointImageScene& scene, const ImageCamera& camera,
                    std::span<const ImageLight> lights, const ImageSettings& settings) {
  if (camera.width < 1 || camera.height < 1) throw UsageError("image-space points: empty image");
  if (settings.layers < 1) throw UsageError("image-space points: --layers must be at least 1");
  if (lights.size() > gpu::kMaxLights)
    throw UsageError("image-space points: at most " + std::to_string(gpu::kMaxLights) + " lights");
  ImagePlan plan;
  plan.layers = settings.layers;
  plan.fillPasses = std::max(settings.maxFillPasses, 0);
  // A hole in a front layer is about a point spacing wide, which the masks' radius follows (at
  // most maxFillRadius): it closes in as many passes, and an occluded pixel is a candidate only
  // in the first r passes (imageFill). More would only go on flattening creases deeper than d̃,
  // a pixel a pass.
  plan.occludedPasses = std::min(plan.fillPasses, std::clamp(settings.maxFillRadius, 1,
                                                             int(gpu::kImageMaxFillRadius)));
  plan.shadows = settings.shadows && !lights.empty();
  plan.reuseShadows = settings.reuseShadows;
  const glm::vec3 lo = scene.lo(), hi = scene.hi();
  const float gap = scene.gap(settings);
  const uint32_t radius =
      uint32_t(std::clamp(settings.maxFillRadius, 1, int(gpu::kImageMaxFillRadius)));
  const uint32_t cull = settings.cull && scene.orientedEverywhere() ? gpu::kImageCull : 0u;

  ImageParams& q = plan.eye;
  q = viewParams(camera.eye, camera.target - camera.eye, camera.up, glm::radians(camera.fovDegrees),
                 camera.width, camera.height, lo, hi);
  plan.far = 1.0f / q.eye.w;
  q.layer.x = gap * q.eye.w;
  q.layer.w = settings.eyeDomeStrength;
  q.image.z = radius;
  uint32_t options = cull;
  if (plan.shadows) options |= gpu::kImageShadows;
  if (settings.eyeDome || !scene.normalsEverywhere()) options |= gpu::kImageEyeDome;
  if (settings.antialias == ImageAntialias::Off) options |= gpu::kImageAaOff;
  if (settings.antialias == ImageAntialias::Edges) options |= gpu::kImageAaEdges;
  if (!settings.smooth) options |= gpu::kImageSmoothOff;
  q.image.w = options;
  q.ambient = glm::vec4(settings.ambient, float(lights.size()));
  q.material = glm::vec4(settings.diffuse, settings.specular, settings.shininess, 0.0f);
  q.background = glm::vec4(settings.background, 0.0f);
  for (size_t l = 0; l < lights.size(); ++l) {
    const int samples = lights[l].area() ? std::max(lights[l].samples, 1) : 1;
    q.lights[l].position = glm::vec4(lights[l].position, float(gpu::kLightPoint));
    q.lights[l].color = glm::vec4(lights[l].color, float(samples));
  }
  if (!plan.shadows) return plan;

  // One square view a sample of each light, from the sample toward the points' box, holding it.
  const glm::vec3 center = 0.5f * (lo + hi);

  for (size_t l = 0; l < lights.size(); ++l) {
    const ImageLight& light = lights[l];
    const int samples = int(q.lights[l].color.w);
    for (int s = 0; s < samples; ++s) {
      const glm::vec2 h = light.area() ? halton(uint32_t(s) + 1u) - 0.5f : glm::vec2(0.0f);
      const glm::vec3 at = light.position + h.x * light.u + h.y * light.v;
      const glm::vec3 forward = glm::normalize(center - at);
      glm::vec3 right = glm::cross(forward, glm::vec3(0, 1, 0));
      if (glm::dot(right, right) < 1e-6f) right = glm::cross(forward, glm::vec3(1, 0, 0));
      right = glm::normalize(right);
      const glm::vec3 up = glm::cross(right, forward);
      float spread = 0.0f;  // the largest tangent of a corner off the axis
      for (int c = 0; c < 8; ++c) {
        const glm::vec3 v =
            glm::vec3((c & 1) ? hi.x : lo.x, (c & 2) ? hi.y : lo.y, (c & 4) ? hi.z : lo.z) - at;
        const float z = glm::dot(v, forward);
        spread = z > 0.0f ? std::max({spread, std::abs(glm::dot(v, right)) / z,
                                      std::abs(glm::dot(v, up)) / z})
                          : 1e9f;
      }
      if (!(spread < 5.0f))
        throw UsageError(
            "image-space shadows: a light too close to the points (a light's view of the points' "
            "box must fit in 2·atan(5) = 157°): move it farther out");
      // The lights' images: the size asked for, or one whose pixels are about the points'
      // spacing where they lie (denser images leave holes between points that the filling
      // must close, and let points behind show through them).
      int size = settings.shadowResolution;
      if (size <= 0) {
        const float across = 2.0f * spread * glm::length(center - at);
        size = int(std::clamp(across / (kShadowPixelSpacings * scene.largestSpacing()), 256.0f,
                              float(std::max(settings.maxShadowResolution, 256))));
      }
      ImageParams v = viewParams(at, forward, up, 2.0f * std::atan(spread * 1.01f), size, size, lo, hi);
      v.layer.x = gap * v.eye.w;
      v.image.z = radius;
      v.image.w = cull;
      v.ambient.w = float(lights.size());
      v.material.w = float(l);
      plan.samples.push_back(v);
      plan.light.push_back(uint32_t(l));
    }
  }
  return plan;
}

uint32_t imagePixelWord(glm::vec3 linear) {
  uint32_t word = 0xFF000000u;
  for (int k = 0; k < 3; ++k) {
    const float v = std::clamp(linear[k], 0.0f, 1.0f);
    const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
    word |= uint32_t(std::lround(s * 255.0f)) << (8 * k);
  }
  return word;
}

PointImageRenderer::PointImageRenderer(std::vector<ImageObject> objects) : scene_(objects) {}

PointImageRenderer::~PointImageRenderer() = default;

void PointImageRenderer::computeShadows(const ImagePlan& plan, size_t lights, ImageStats& stats) {
  // The shadow textures stay while the lights' samples do (the points never move): the paper's
  // reuse of a texture while light and object stay put.
  std::vector<float> key;
  for (const ImageParams& q : plan.samples) {
    const float* words = &q.eye.x;
    key.insert(key.end(), words, words + sizeof(ImageParams) / sizeof(float));
  }
  const size_t n = scene_.size();
  if (plan.reuseShadows && key == shadowKey_ && shadow_.size() == n * lights) {
    stats.shadowsReused = true;
    return;
  }
  std::vector<uint32_t> lit(n * lights, 0);
  for (size_t s = 0; s < plan.samples.size(); ++s) {
    Pass pass(plan.samples[s], scene_, nullptr, 0);
    Layer layer = project(pass, n, [](uint32_t, glm::ivec2, float) { return true; });
    // Only occluded pixels are filled (section 6): a background hole filled from the nearest
    // neighbour would grow the occluders' silhouettes over the surfaces behind them.
    fill(pass, layer, plan.fillPasses, plan.occludedPasses, true);
    pass.layer = &layer;
    const size_t l = plan.light[s];
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const auto& range) {
      for (size_t i = range.begin(); i != range.end(); ++i)
        if (pass.imageLit(pass.pointPosition(uint32_t(i)), pass.pointNormal(uint32_t(i))))
          ++lit[i * lights + l];
    });
    stats.projected += 2 * n;
  }
  shadow_.assign(n * lights, 0.0f);
  for (size_t i = 0; i < n; ++i)
    for (size_t l = 0; l < lights; ++l)
      shadow_[i * lights + l] = float(lit[i * lights + l]) / plan.eye.lights[l].color.w;
  shadowKey_ = std::move(key);
}

ImageResult PointImageRenderer::render(const ImageCamera& camera, std::span<const ImageLight> lights,
                                       const ImageSettings& settings) {
  const ImagePlan plan = planImage(scene_, camera, lights, settings);
  ImageResult result;
  result.width = camera.width;
  result.height = camera.height;
  const size_t pixels = size_t(camera.width) * camera.height;
  if (plan.shadows) computeShadows(plan, lights.size(), result.stats);

  Pass pass(plan.eye, scene_, shadow_.data(), uint32_t(lights.size()));
  std::vector<glm::vec4> sum(pixels, glm::vec4(0.0f));
  Layer last;
  for (int k = 0; k < plan.layers; ++k) {
    pass.Q.image.w = plan.eye.image.w | (k > 0 ? gpu::kImagePeel : 0u);
    pass.reference = &last;
    Layer layer = project(pass, scene_.size(), [&](uint32_t, glm::ivec2 pixel, float depth) {
      return pass.imageBehindLast(pixel, depth);
    });
    result.stats.projected += scene_.size();
    if (std::all_of(layer.index.begin(), layer.index.end(),
                    [](uint32_t i) { return i == kImageNoPoint; }))
      break;
    const auto [background, occluded] = fill(pass, layer, plan.fillPasses, plan.occludedPasses);
    result.stats.backgroundPasses.push_back(background);
    result.stats.occludedPasses.push_back(occluded);
    ++result.stats.layers;
    const std::vector<glm::vec4> rgba = shade(pass, layer);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pixels), [&](const auto& range) {
      for (size_t i = range.begin(); i != range.end(); ++i) sum[i] += (1.0f - sum[i].a) * rgba[i];
    });
    if (k == 0) {
      result.depth.resize(pixels);
      for (size_t i = 0; i < pixels; ++i) result.depth[i] = layer.depth[i] * plan.far;
      result.points = layer.index;
    }
    last = std::move(layer);
  }
  if (result.points.empty()) {
    result.depth.assign(pixels, 0.0f);
    result.points.assign(pixels, kImageNoPoint);
  }
  result.color.resize(pixels);
  result.coverage.resize(pixels);
  for (size_t i = 0; i < pixels; ++i) {
    result.color[i] = glm::vec3(sum[i]) + (1.0f - sum[i].a) * glm::vec3(plan.eye.background);
    result.coverage[i] = sum[i].a;
  }
  return result;
}

}  // namespace iso::viewer
