// Placeholder until the draco reader lands.
#include "io/point_readers.h"
#include "iso/error.h"
namespace iso::io {
std::unique_ptr<PointReader> makeDracoReader(InputStream in) {
  throw FileError(in.name(), std::nullopt, "draco files are not supported yet");
}
}  // namespace iso::io
