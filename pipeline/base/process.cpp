#include "pipeline/base/process.h"

#include <unistd.h>

#include <cstdio>

namespace iso {

uint64_t currentRssBytes(uint64_t* fromFiles) {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (fromFiles) *fromFiles = 0;
  if (f == nullptr) return 0;
  unsigned long long pages = 0, resident = 0, shared = 0;
  const int read = std::fscanf(f, "%llu %llu %llu", &pages, &resident, &shared);
  std::fclose(f);
  const auto page = uint64_t(sysconf(_SC_PAGESIZE));
  if (fromFiles && read == 3) *fromFiles = shared * page;
  return read >= 2 ? resident * page : 0;
}

uint64_t peakRssBytes() {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (f == nullptr) return 0;
  char line[256];
  unsigned long long kib = 0;
  while (std::fgets(line, sizeof line, f))
    if (std::sscanf(line, "VmHWM: %llu kB", &kib) == 1) break;
  std::fclose(f);
  return kib * 1024;
}

void resetPeakRss() {
  if (std::FILE* f = std::fopen("/proc/self/clear_refs", "w")) {
    std::fputs("5", f);
    std::fclose(f);
  }
}

}  // namespace iso
