// Progress of long work, for people: on a terminal one live line per stage (percent, points/s,
// ETA, resident memory), rewritten in place; elsewhere, when asked, one JSON object per update.
//
// Stages count their work with the free function progressAdvance(), which costs one relaxed
// atomic add and works whether or not a reporter is running; a background thread of the reporter
// samples the count a few times a second, so hot loops never print or lock.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "base/text.h"

namespace iso {

// Count `amount` units of work (usually points) done in the current stage. Thread-safe.
void progressAdvance(uint64_t amount);

// While one lives, progressAdvance counts nothing: a stage that counts its own units (chunks of
// points) runs inner steps that would count theirs too.
class ProgressMute {
 public:
  ProgressMute();
  ~ProgressMute();
  ProgressMute(const ProgressMute&) = delete;
  ProgressMute& operator=(const ProgressMute&) = delete;
};

enum class ProgressMode {
  None,  // report nothing
  Line,  // a live line on a terminal
  Json,  // one JSON object per line
};
inline constexpr NameTable<ProgressMode, 3> kProgressNames{
    {{"line", ProgressMode::Line}, {"json", ProgressMode::Json}, {"none", ProgressMode::None}}};

class ProgressReporter {
 public:
  // Reports to `out` every `interval` while a stage runs; one reporter at a time.
  explicit ProgressReporter(ProgressMode mode, std::FILE* out = stderr,
                            std::chrono::milliseconds interval = std::chrono::milliseconds(250));
  ~ProgressReporter();
  ProgressReporter(const ProgressReporter&) = delete;
  ProgressReporter& operator=(const ProgressReporter&) = delete;

  // Start a stage of `total` units (0: unknown; then no percent or ETA). Ends the previous one.
  void begin(const std::string& stage, uint64_t total);
  // End the current stage: the final line (Line) or an "end" object (Json).
  void end();
  // Call `observer` with the name of each stage begun from now on, as it begins (in the thread
  // that calls begin()); whatever the mode, None included.
  void observeStages(std::function<void(const std::string& stage)> observer);

 private:
  void run();
  void print(bool final);

  ProgressMode mode_;
  std::FILE* out_;
  std::chrono::milliseconds interval_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  bool active_ = false;
  std::string stage_;
  std::function<void(const std::string&)> observer_;
  uint64_t total_ = 0;
  std::chrono::steady_clock::time_point started_;
  std::thread thread_;
};

}  // namespace iso
