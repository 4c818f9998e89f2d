#include "pipeline/io/non_finite.h"

#include <algorithm>

namespace iso::io {

size_t removeNonFinite(PointCloud& out, size_t first) {
  const auto firstInvalid =
      std::find_if(out.positions.begin() + ptrdiff_t(first), out.positions.end(),
                   [](const glm::dvec3& p) { return !isFinite(p); });
  if (firstInvalid == out.positions.end()) return 0;
  const size_t extraCount = out.extraCount();
  size_t written = size_t(firstInvalid - out.positions.begin());
  for (size_t i = written; i < out.positions.size(); ++i) {
    if (!isFinite(out.positions[i])) continue;
    out.positions[written] = out.positions[i];
    if (out.hasNormals()) out.normals[written] = out.normals[i];
    if (out.hasColors()) out.colors[written] = out.colors[i];
    std::copy_n(out.extras.begin() + ptrdiff_t(i * extraCount), extraCount,
                out.extras.begin() + ptrdiff_t(written * extraCount));
    ++written;
  }
  const size_t removed = out.positions.size() - written;
  out.positions.resize(written);
  if (out.hasNormals()) out.normals.resize(written);
  if (out.hasColors()) out.colors.resize(written);
  out.extras.resize(written * extraCount);
  return removed;
}

}  // namespace iso::io
