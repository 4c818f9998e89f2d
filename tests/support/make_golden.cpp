// make_golden OUT: write tests/data/golden-v2.iso (only when the format changes on purpose).
// make_golden --points OUT: write a small file of points chunks (a seed for the fuzzer).
// make_golden --lighting GOLDEN OUT: GOLDEN with lighting chunks (a seed for the fuzzer).
#include <cstdio>
#include <cstring>

#include "tests/support/support.h"

int main(int argc, char** argv) {
  if (argc == 3 && std::strcmp(argv[1], "--points") == 0) {
    iso::test::writePointsSeedFile(argv[2]);
    return 0;
  }
  if (argc == 4 && std::strcmp(argv[1], "--lighting") == 0) {
    iso::test::writeLightingSeedFile(argv[2], argv[3]);
    return 0;
  }
  if (argc != 2) {
    std::fprintf(stderr,
                 "usage: make_golden OUT.iso | make_golden --points OUT.iso | make_golden "
                 "--lighting GOLDEN.iso OUT.iso\n");
    return 2;
  }
  iso::test::writeGoldenFile(argv[1]);
  return 0;
}
