// consumer FILE.iso EXPECTED_CHUNKS: open a file with the installed library and check it.
#include <cstdio>
#include <string>

#include "iso/reader.h"
#include "iso/verify.h"

int main(int argc, char** argv) {
  if (argc != 3) return 2;
  try {
    const iso::Reader reader = iso::Reader::open(argv[1]);
    const bool ok = iso::verifyFile(reader).ok() && reader.chunks().size() == std::stoul(argv[2]);
    std::printf("%s: %zu chunks, %s\n", argv[1], reader.chunks().size(), ok ? "ok" : "unexpected");
    return ok ? 0 : 1;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "%s\n", error.what());
    return 1;
  }
}
