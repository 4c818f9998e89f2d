// Synthetic scans: area-uniform samples thinned by a density ramp along x, displaced along the true
// normal by Gaussian noise, generated in fixed blocks with independent seeds so that the result
// does not depend on the number of threads.
#include "pipeline/geom/generate.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "iso/error.h"
#include "pipeline/geom/random.h"

namespace iso {
namespace {

// Points per block. Part of the definition of a scan: changing it changes every scan of a seed.
constexpr uint64_t kBlockSize = uint64_t{1} << 16;

void validate(const GenerateOptions& o) {
  if (o.count == 0) throw UsageError("generate: the point count must be positive");
  if (!std::isfinite(o.noise) || o.noise < 0.0)
    throw UsageError("generate: noise must be a finite number >= 0, not " +
                                std::to_string(o.noise));
  if (!std::isfinite(o.densityRatio) || o.densityRatio < 1.0)
    throw UsageError("generate: the density ratio must be a finite number >= 1, not " +
                                std::to_string(o.densityRatio));
  if (!std::isfinite(o.offset.x) || !std::isfinite(o.offset.y) || !std::isfinite(o.offset.z))
    throw UsageError("generate: the offset must be finite");
}

class ScanSampler {
 public:
  ScanSampler(const Shape& shape, const GenerateOptions& options)
      : shape_(shape),
        options_(options),
        sigma_(options.noise * expectedSpacing(shape.area(), options.count)),
        xMin_(shape.boundsMin().x),
        xWidth_(shape.boundsMax().x - shape.boundsMin().x) {}

  // Points [first, end) of the scan, drawn from block `block`'s own generator, seeded with
  // mix(mix(seed) + block).
  void fillBlock(uint64_t block, uint64_t first, uint64_t end, PointCloud& out) const {
    std::mt19937_64 rng(mixBits(mixBits(options_.seed) + block));
    for (uint64_t i = first; i < end; ++i) {
      SurfacePoint s = shape_.sample(rng);
      while (!accept(s.position.x, rng)) s = shape_.sample(rng);
      glm::dvec3 p = s.position;
      if (sigma_ > 0.0) p += (sigma_ * standardNormal(rng)) * s.normal;
      out.positions[i] = p + options_.offset;
      if (options_.normals) out.normals[i] = glm::vec3(s.normal);
    }
  }

 private:
  // Thinning (Lewis and Shedler 1979) to the relative density ratio^u, u = (x - xmin) / width:
  // accept with probability ratio^(u - 1), 1 at the dense end.
  bool accept(double x, std::mt19937_64& rng) const {
    if (options_.densityRatio == 1.0) return true;
    const double u = xWidth_ > 0.0 ? (x - xMin_) / xWidth_ : 0.0;
    return uniform01(rng) < std::pow(options_.densityRatio, u - 1.0);
  }

  const Shape& shape_;
  const GenerateOptions& options_;
  double sigma_;
  double xMin_;
  double xWidth_;
};

}  // namespace

double expectedSpacing(double area, uint64_t count) {
  return 0.5 / std::sqrt(double(count) / area);
}

PointCloud generateScan(const Shape& shape, const GenerateOptions& options) {
  validate(options);
  PointCloud cloud;
  cloud.positions.resize(options.count);
  if (options.normals) cloud.normals.resize(options.count);
  const ScanSampler sampler(shape, options);
  const uint64_t blocks = (options.count + kBlockSize - 1) / kBlockSize;
  tbb::parallel_for(uint64_t(0), blocks, [&](uint64_t block) {
    const uint64_t first = block * kBlockSize;
    sampler.fillBlock(block, first, std::min(first + kBlockSize, options.count), cloud);
  });
  return cloud;
}

}  // namespace iso
