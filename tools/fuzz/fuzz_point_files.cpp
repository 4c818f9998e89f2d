// libFuzzer target for the readers of point files, LAZ and E57 among them: any bytes, under a name
// the first byte chooses (the readers choose by signature first, then by extension), must read to
// the end or give a FileError, never a crash, undefined behaviour or a runaway allocation. The
// bytes go through a file because readers take paths.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "iso/error.h"
#include "pipeline/io/readers.h"

namespace {

constexpr const char* kExtensions[] = {".laz", ".e57", ".las", ".ply", ".pcd", ".xyz", ".drc"};

std::filesystem::path scratch(const char* extension) {
  return std::filesystem::temp_directory_path() /
         ("iso-fuzz-point-" + std::to_string(getpid()) + extension);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const char* extension = kExtensions[data[0] % std::size(kExtensions)];
  const std::filesystem::path path = scratch(extension);
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data + 1), std::streamsize(size - 1));
  try {
    const auto reader = iso::openPointFile(path, {.columns = "", .keepExtras = true});
    iso::PointCloud batch;
    for (int batches = 0; batches < 8; ++batches) {
      batch.clear();
      if (reader->read(batch, 1024) == 0) break;
    }
  } catch (const iso::FileError&) {
  }
  std::filesystem::remove(path);
  return 0;
}
