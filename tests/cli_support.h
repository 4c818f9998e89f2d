// Running the `iso` program as a user would, for the command-line tests (ISO_BINARY is its path).
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <string>

#include "tests/support/support.h"

namespace iso::test {

struct CommandResult {
  int exitCode = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

inline std::string slurp(const std::filesystem::path& path) {
  const std::vector<std::byte> bytes = readFile(path);
  return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
}

inline CommandResult runIso(const std::string& arguments) {
  TempDir dir;
  const std::string command = std::string(ISO_BINARY) + " " + arguments + " >" +
                              (dir / "out").string() + " 2>" + (dir / "err").string();
  const int status = std::system(command.c_str());
  CommandResult run;
  run.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.out = slurp(dir / "out");
  run.err = slurp(dir / "err");
  return run;
}

inline std::string quoted(const std::filesystem::path& path) { return "'" + path.string() + "'"; }

}  // namespace iso::test
