// Temporary files that must not outlive an interrupted run.
//
// Every temporary file iso writes is named ".NAME.PID-N.isotmp" (PID: the writing process). Files
// registered here are removed by the handlers installInterruptCleanup() puts on SIGINT, SIGTERM and
// SIGHUP (Ctrl-C, kill, a closed terminal) before the process ends with that signal, or by a
// program's own handler through removeRegisteredTemporaries(). A process
// killed with SIGKILL cannot clean up: removeStaleTemporaries() then removes, on the next run, the
// temporary files of processes that no longer exist.
#pragma once

#include <cstddef>
#include <filesystem>

namespace iso {

// Keeps `path` registered for removal on interruption while the object lives (a directory is
// removed after the files registered, when they were all it held). Registration is
// cheap (a fixed table, no allocation); when the table is full the path is simply not registered.
class TemporaryRegistration {
 public:
  TemporaryRegistration() = default;
  explicit TemporaryRegistration(const std::filesystem::path& path);
  ~TemporaryRegistration();
  TemporaryRegistration(TemporaryRegistration&& other) noexcept;
  TemporaryRegistration& operator=(TemporaryRegistration&& other) noexcept;
  TemporaryRegistration(const TemporaryRegistration&) = delete;
  TemporaryRegistration& operator=(const TemporaryRegistration&) = delete;

 private:
  int slot_ = -1;
};

// Install the signal handlers (once per process; later calls do nothing): on SIGINT, SIGTERM and
// SIGHUP they remove the registered paths and end the process with that signal. A signal the
// process was started ignoring (nohup, a background job of a shell) stays ignored.
void installInterruptCleanup();

// Remove every registered path now: the files, then the directories that are empty by then
// (deepest first). Async-signal-safe, for a program's own signal handler.
void removeRegisteredTemporaries() noexcept;

// Remove the temporary files ".NAME.PID-N.isotmp" in `directory` whose process PID is gone; returns
// how many were removed. Files of live processes (and anything else) are left alone.
size_t removeStaleTemporaries(const std::filesystem::path& directory);

// Whether a file name is one of iso's temporary names, and the process that wrote it.
bool parseTemporaryName(const std::string& name, long& pid);

}  // namespace iso
