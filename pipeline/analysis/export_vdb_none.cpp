// The OpenVDB export (pipeline/analysis/export.h) in builds without OpenVDB (ISO_WITH_OPENVDB=OFF):
// every use says so.
#include "iso/error.h"
#include "pipeline/analysis/export.h"

namespace iso {

void requireOpenVdb(const std::string& option) {
  throw UsageError(option +
                   ": this build of iso has no OpenVDB (it was built with ISO_WITH_OPENVDB=OFF)");
}

std::vector<double> sampleVdb(const std::filesystem::path&, std::span<const glm::dvec3>) {
  requireOpenVdb("reading an OpenVDB file");
  return {};
}

VdbStats writeVdb(const SurfaceModel&, const std::filesystem::path&, double) {
  requireOpenVdb("the OpenVDB level set");
  return {};
}

}  // namespace iso
