// make_golden OUT: write tests/data/golden-v1.iso (only when the format changes on purpose).
#include <cstdio>

#include "support.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_golden OUT.iso\n");
    return 2;
  }
  iso::test::writeGoldenFile(argv[1]);
  return 0;
}
