// LAZ files for the benchmarks and tests: a LAS file of point format 0 compressed as LASzip
// does (POINT10 version 2, chunks of a fixed size). Neither Debian 12 nor npm has a LAZ encoder
// (npm's laz-perf build decodes only), so `tools/run bench read` makes its large LAZ inputs
// here; what it writes is checked by decoding it with laz-perf (tests/io/laz_writer_test.cpp).
#pragma once

#include <cstdint>
#include <filesystem>

namespace iso::bench {

// Compress `las` (LAS 1.0–1.3, point format 0, no EVLRs) into `laz`, in chunks of `chunkSize`
// points (LASzip's default 50,000), keeping its header and VLRs. Throws iso::FileError.
void writeLazFromLas(const std::filesystem::path& las, const std::filesystem::path& laz,
                     uint32_t chunkSize = 50000);

}  // namespace iso::bench
