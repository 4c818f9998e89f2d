// What SIGINT (Ctrl-C), SIGTERM and SIGHUP (a closed terminal) do to the `iso` program: remove the
// temporary files (iso/temporary_files.h: partial outputs are temporary files until renamed into
// place), print one line on stderr saying what was interrupted and what that left, and end the
// process by the same signal, so that a shell reports 128 + the signal (130 for Ctrl-C, 143 for
// kill) and a script that runs iso stops as it would for any program. A signal the process was
// started ignoring (nohup, a background job of a non-interactive shell) stays ignored.
#pragma once

#include <string_view>

namespace iso::cli {

// Install the handlers (once, before any command runs).
void installInterruptHandlers();

// The line printed on interruption from now on ("iso convert: interrupted while ...; nothing was
// written"; a newline is added, and one put first when `afterLiveLine`: a progress line may be
// half drawn). Longer lines are cut. Thread-safe; the handler reads it without locking.
void setInterruptMessage(std::string_view line, bool afterLiveLine = false);

// While one lives, a signal waits: it is acted on when the last one ends (while outputs are
// renamed into place, all or none, an interruption must not cut the renames short).
class InterruptsDeferred {
 public:
  InterruptsDeferred();
  ~InterruptsDeferred();
  InterruptsDeferred(const InterruptsDeferred&) = delete;
  InterruptsDeferred& operator=(const InterruptsDeferred&) = delete;
};

}  // namespace iso::cli
