#include "tools/iso/interrupt.h"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstring>

#include "iso/temporary_files.h"

namespace iso::cli {
namespace {

// The message, in a ring of slots so that the handler never reads a slot being written (a new
// message goes to the next slot, then becomes the current one).
struct Message {
  std::array<char, 1024> text{};
  size_t length = 0;
};
std::array<Message, 8> gMessages;
std::atomic<size_t> gCurrent{0};

std::atomic<int> gDeferring{0};
std::atomic<int> gPending{0};
std::atomic<bool> gHandling{false};

// Only async-signal-safe work: atomics, unlink/rmdir, write, sigaction, raise.
void endBy(int signal) {
  if (gHandling.exchange(true)) return;  // another thread is ending the process already
  removeRegisteredTemporaries();
  const Message& m = gMessages[gCurrent.load(std::memory_order_acquire)];
  for (size_t written = 0; written < m.length;) {
    const ssize_t n = ::write(STDERR_FILENO, m.text.data() + written, m.length - written);
    if (n <= 0) break;
    written += size_t(n);
  }
  struct sigaction action {};
  action.sa_handler = SIG_DFL;
  sigemptyset(&action.sa_mask);
  ::sigaction(signal, &action, nullptr);
  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, signal);
  ::pthread_sigmask(SIG_UNBLOCK, &mask, nullptr);
  ::raise(signal);
}

extern "C" void onSignal(int signal) {
  gPending.store(signal);
  if (gDeferring.load() > 0) return;  // InterruptsDeferred acts on it
  endBy(signal);
}

}  // namespace

void installInterruptHandlers() {
  setInterruptMessage("iso: interrupted");
  struct sigaction action {};
  action.sa_handler = onSignal;
  sigemptyset(&action.sa_mask);
  const int signals[] = {SIGINT, SIGTERM, SIGHUP};
  for (int s : signals) sigaddset(&action.sa_mask, s);  // one at a time
  for (int s : signals) {
    struct sigaction previous {};
    if (::sigaction(s, nullptr, &previous) == 0 && previous.sa_handler == SIG_IGN) continue;
    ::sigaction(s, &action, nullptr);
  }
}

void setInterruptMessage(std::string_view line, bool afterLiveLine) {
  static std::atomic<size_t> next{1};
  const size_t slot = next.fetch_add(1) % gMessages.size();
  Message& m = gMessages[slot];
  size_t length = 0;
  if (afterLiveLine) m.text[length++] = '\n';
  const size_t room = m.text.size() - length - 1;
  const size_t n = std::min(line.size(), room);
  std::memcpy(m.text.data() + length, line.data(), n);
  length += n;
  m.text[length++] = '\n';
  m.length = length;
  gCurrent.store(slot, std::memory_order_release);
}

InterruptsDeferred::InterruptsDeferred() { gDeferring.fetch_add(1); }

InterruptsDeferred::~InterruptsDeferred() {
  if (gDeferring.fetch_sub(1) != 1) return;
  if (const int signal = gPending.exchange(0); signal != 0) endBy(signal);
}

}  // namespace iso::cli
