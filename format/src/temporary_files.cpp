#include "iso/temporary_files.h"

#include <signal.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <string>

namespace iso {
namespace {

// The table the signal handler reads: only async-signal-safe work happens there (reading atomics
// and fixed arrays, unlink()). A slot's path is written before the slot is marked in use.
constexpr int kSlots = 64;
constexpr size_t kPathBytes = 4096;
struct Slot {
  std::atomic<int> state{0};  // 0 free, 1 being written, 2 in use
  char path[kPathBytes];
};
std::array<Slot, kSlots> gSlots;

extern "C" void removeAndReraise(int signal) {
  removeRegisteredTemporaries();
  ::signal(signal, SIG_DFL);
  ::raise(signal);
}

bool isAlive(long pid) { return ::kill(pid_t(pid), 0) == 0 || errno == EPERM; }

}  // namespace

TemporaryRegistration::TemporaryRegistration(const std::filesystem::path& path) {
  const std::string& text = path.native();
  if (text.size() >= kPathBytes) return;
  for (int i = 0; i < kSlots; ++i) {
    int expected = 0;
    if (!gSlots[size_t(i)].state.compare_exchange_strong(expected, 1)) continue;
    std::memcpy(gSlots[size_t(i)].path, text.c_str(), text.size() + 1);
    gSlots[size_t(i)].state.store(2, std::memory_order_release);
    slot_ = i;
    return;
  }
}

TemporaryRegistration::~TemporaryRegistration() {
  if (slot_ >= 0) gSlots[size_t(slot_)].state.store(0, std::memory_order_release);
}

TemporaryRegistration::TemporaryRegistration(TemporaryRegistration&& other) noexcept
    : slot_(other.slot_) {
  other.slot_ = -1;
}

TemporaryRegistration& TemporaryRegistration::operator=(TemporaryRegistration&& other) noexcept {
  if (this != &other) {
    if (slot_ >= 0) gSlots[size_t(slot_)].state.store(0, std::memory_order_release);
    slot_ = other.slot_;
    other.slot_ = -1;
  }
  return *this;
}

void removeRegisteredTemporaries() noexcept {
  for (Slot& slot : gSlots)
    if (slot.state.load(std::memory_order_acquire) == 2) ::unlink(slot.path);
  // Directories once the files in them are gone, deepest first: a pass removes those that are
  // empty by then, until a pass removes none.
  for (bool removed = true; removed;) {
    removed = false;
    for (Slot& slot : gSlots)
      if (slot.state.load(std::memory_order_acquire) == 2 && ::rmdir(slot.path) == 0)
        removed = true;
  }
}

void installInterruptCleanup() {
  static std::atomic<bool> installed{false};
  if (installed.exchange(true)) return;
  struct sigaction action {};
  action.sa_handler = removeAndReraise;
  sigemptyset(&action.sa_mask);
  for (int signal : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction previous {};
    // A signal the process was started ignoring (nohup, a background job) stays ignored.
    if (::sigaction(signal, nullptr, &previous) == 0 && previous.sa_handler == SIG_IGN) continue;
    ::sigaction(signal, &action, nullptr);
  }
}

bool parseTemporaryName(const std::string& name, long& pid) {
  constexpr std::string_view kSuffix = ".isotmp";
  if (name.size() < kSuffix.size() + 4 || name[0] != '.' || !name.ends_with(kSuffix)) return false;
  const std::string_view stem(name.data(), name.size() - kSuffix.size());  // ".NAME.PID-N"
  const size_t dot = stem.rfind('.');
  const size_t dash = stem.rfind('-');
  if (dot == 0 || dot == std::string_view::npos || dash == std::string_view::npos || dash < dot)
    return false;
  const char* first = stem.data() + dot + 1;
  const char* last = stem.data() + dash;
  const auto parsed = std::from_chars(first, last, pid);
  return parsed.ec == std::errc() && parsed.ptr == last && pid > 0;
}

size_t removeStaleTemporaries(const std::filesystem::path& directory) {
  size_t removed = 0;
  std::error_code error;
  const std::filesystem::path where = directory.empty() ? "." : directory;
  for (const auto& entry : std::filesystem::directory_iterator(where, error)) {
    long pid = 0;
    if (!parseTemporaryName(entry.path().filename().string(), pid) || isAlive(pid)) continue;
    std::error_code ignored;
    if (std::filesystem::remove_all(entry.path(), ignored) > 0) ++removed;
  }
  return removed;
}

}  // namespace iso
