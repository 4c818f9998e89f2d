// Running the `iso` program as a user would, for the command-line tests (ISO_BINARY is its path).
#pragma once

#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <string>

#include "tests/support/support.h"

namespace iso::test {

struct CommandResult {
  int exitCode = -1;
  std::string out;      // stdout
  std::string err;      // stderr
  long peakRssKiB = 0;  // the command's peak resident memory (the kernel's ru_maxrss)
};

inline std::string slurp(const std::filesystem::path& path) {
  const std::vector<std::byte> bytes = readFile(path);
  return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
}

// A shell command line, its output captured.
inline CommandResult runCommand(const std::string& commandLine) {
  TempDir dir;
  const std::string command =
      commandLine + " >" + (dir / "out").string() + " 2>" + (dir / "err").string();
  // The shell is waited for with wait4, which also gives the peak memory of what it ran.
  const char* argv[] = {"/bin/sh", "-c", command.c_str(), nullptr};
  CommandResult run;
  pid_t pid = 0;
  if (posix_spawn(&pid, "/bin/sh", nullptr, nullptr, const_cast<char* const*>(argv), environ) != 0)
    return run;
  int status = 0;
  rusage usage{};
  while (wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
  }
  run.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.peakRssKiB = usage.ru_maxrss;
  run.out = slurp(dir / "out");
  run.err = slurp(dir / "err");
  return run;
}

inline CommandResult runIso(const std::string& arguments) {
  return runCommand(std::string(ISO_BINARY) + " " + arguments);
}

inline std::string quoted(const std::filesystem::path& path) { return "'" + path.string() + "'"; }

}  // namespace iso::test
