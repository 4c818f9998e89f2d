// Environment maps (image.h): any image that reads, as float16 pairs.
#include <glm/glm.hpp>
#include <glm/packing.hpp>

#include "base/image.h"
#include "iso/error.h"

namespace iso {

Environment loadEnvironment(const std::filesystem::path& path, uint32_t maxWidth) {
  const LinearImage image = readLinearImage(path, maxWidth);
  if (image.width < 2)
    throw FileError(path.string(), std::nullopt, "the environment map is too small");
  Environment env;
  env.width = image.width;
  env.height = image.height;
  env.texels.resize(image.texels.size() * 2);
  for (size_t i = 0; i < image.texels.size(); ++i) {
    const glm::vec3& c = image.texels[i];
    env.texels[2 * i] = glm::packHalf2x16({c.r, c.g});
    env.texels[2 * i + 1] = glm::packHalf2x16({c.b, 0.0f});
  }
  return env;
}

}  // namespace iso
