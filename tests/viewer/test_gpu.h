// The one Vulkan device of viewer_test (lavapipe in CI), with the validation layer on.
#pragma once

#include "viewer/vulkan.h"

namespace iso::test {

viewer::Gpu& testGpu();

}  // namespace iso::test
