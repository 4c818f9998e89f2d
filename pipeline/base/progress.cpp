#include "pipeline/base/progress.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "pipeline/base/buffers.h"
#include "pipeline/base/process.h"
#include "base/text.h"

namespace iso {
namespace {

std::atomic<uint64_t> gDone{0};
std::atomic<int> gMuted{0};

std::string rate(double perSecond) {
  if (perSecond >= 1e6) return fmt::format("{:.2f}M/s", perSecond / 1e6);
  if (perSecond >= 1e3) return fmt::format("{:.1f}k/s", perSecond / 1e3);
  return fmt::format("{:.0f}/s", perSecond);
}

std::string clock(double seconds) {
  const auto s = static_cast<uint64_t>(std::max(0.0, std::round(seconds)));
  return s >= 3600 ? fmt::format("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
                   : fmt::format("{}:{:02}", s / 60, s % 60);
}

}  // namespace

void progressAdvance(uint64_t amount) {
  spillPause();
  if (gMuted.load(std::memory_order_relaxed) == 0)
    gDone.fetch_add(amount, std::memory_order_relaxed);
}

ProgressMute::ProgressMute() { gMuted.fetch_add(1, std::memory_order_relaxed); }
ProgressMute::~ProgressMute() { gMuted.fetch_sub(1, std::memory_order_relaxed); }

ProgressReporter::ProgressReporter(ProgressMode mode, std::FILE* out,
                                   std::chrono::milliseconds interval)
    : mode_(mode), out_(out), interval_(interval) {
  if (mode_ != ProgressMode::None) thread_ = std::thread([this] { run(); });
}

ProgressReporter::~ProgressReporter() {
  end();
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void ProgressReporter::observeStages(std::function<void(const std::string& stage)> observer) {
  observer_ = std::move(observer);
}

void ProgressReporter::begin(const std::string& stage, uint64_t total) {
  end();
  if (observer_) observer_(stage);
  std::lock_guard lock(mutex_);
  stage_ = stage;
  total_ = total;
  started_ = std::chrono::steady_clock::now();
  gDone.store(0, std::memory_order_relaxed);
  active_ = true;
}

void ProgressReporter::end() {
  std::lock_guard lock(mutex_);
  if (!active_) return;
  print(true);
  active_ = false;
}

void ProgressReporter::run() {
  std::unique_lock lock(mutex_);
  while (!stopping_) {
    wake_.wait_for(lock, interval_);
    if (active_ && !stopping_) print(false);
  }
}

// Called with mutex_ held.
void ProgressReporter::print(bool final) {
  if (mode_ == ProgressMode::None) return;
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  // A stage that ends has done all its work, whether or not it counted every unit.
  const uint64_t counted = gDone.load(std::memory_order_relaxed);
  const uint64_t done = final ? std::max(counted, total_) : counted;
  const double perSecond = elapsed > 0.0 ? double(done) / elapsed : 0.0;
  const bool bounded = total_ > 0 && done <= total_;
  const double fraction = bounded ? double(done) / double(total_) : 0.0;
  const double eta = bounded && perSecond > 0.0 ? double(total_ - done) / perSecond : -1.0;
  uint64_t rssFiles = 0;
  const uint64_t rss = currentRssBytes(&rssFiles);
  if (mode_ == ProgressMode::Json) {
    nlohmann::json j = {
        {"event", final ? "end" : "progress"}, {"stage", stage_},         {"done", done},
        {"elapsed_seconds", elapsed},          {"per_second", perSecond}, {"rss_bytes", rss},
        {"rss_file_bytes", rssFiles}};
    if (total_ > 0) j["total"] = total_;
    if (bounded) j["percent"] = 100.0 * fraction;
    if (eta >= 0.0 && !final) j["eta_seconds"] = eta;
    fmt::print(out_, "{}\n", j.dump());
  } else {
    std::string line = fmt::format("{:<16}", stage_);
    if (bounded) line += fmt::format(" {:5.1f}%", 100.0 * fraction);
    if (done > 0) line += " " + rate(perSecond);
    line += final ? fmt::format(" in {}", clock(elapsed))
                  : (eta >= 0.0 ? fmt::format(" ETA {}", clock(eta)) : "");
    line += " RSS " + byteSize(rss);
    fmt::print(out_, "\r\033[K{}{}", line, final ? "\n" : "");
  }
  std::fflush(out_);
}

}  // namespace iso
