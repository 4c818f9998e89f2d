// The E57 reader (ASTM E2807). Placeholder until the reader lands.
#include "iso/error.h"
#include "pipeline/io/point_readers.h"

namespace iso::io {

std::unique_ptr<PointReader> makeE57Reader(InputStream in, const ReadOptions&) {
  in.failAt(0, "E57 reading is not built yet");
}

}  // namespace iso::io
