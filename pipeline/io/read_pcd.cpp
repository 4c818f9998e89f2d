// Placeholder until the pcd reader lands.
#include "io/point_readers.h"
#include "iso/error.h"
namespace iso::io {
std::unique_ptr<PointReader> makePcdReader(InputStream in) {
  throw FileError(in.name(), std::nullopt, "pcd files are not supported yet");
}
}  // namespace iso::io
