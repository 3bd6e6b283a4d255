#include "covoxslam/core/stage_profiler.h"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <utility>

namespace covox {

namespace {

struct StageTotal {
  int64_t calls = 0;
  int64_t nanoseconds = 0;
  int64_t first_seen = 0;  // keeps the stages in the order the algorithm runs them
};

std::mutex& totals_mutex() {
  static std::mutex mutex;
  return mutex;
}
std::map<std::string, StageTotal>& totals() {
  static std::map<std::string, StageTotal> stages;
  return stages;
}

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

bool StageProfiler::enabled() {
  static const bool on = [] {
    const char* value = std::getenv("COVOX_PROFILE_STAGES");
    return value && *value && std::strcmp(value, "0") != 0;
  }();
  return on;
}

bool StageProfiler::synchronises() {
  static const bool host_only = [] {
    const char* value = std::getenv("COVOX_PROFILE_STAGES");
    return value && std::strcmp(value, "host") == 0;
  }();
  return !host_only;
}

void StageProfiler::add(const char* algorithm, const char* stage, int64_t nanoseconds) {
  std::lock_guard<std::mutex> lock(totals_mutex());
  auto& stages = totals();
  const std::string key = std::string(algorithm) + "/" + stage;
  auto it = stages.find(key);
  if (it == stages.end()) {
    it = stages.emplace(key, StageTotal{}).first;
    it->second.first_seen = static_cast<int64_t>(stages.size());
  }
  ++it->second.calls;
  it->second.nanoseconds += nanoseconds;
}

std::string StageProfiler::report() {
  std::lock_guard<std::mutex> lock(totals_mutex());
  std::multimap<int64_t, std::pair<std::string, StageTotal>> ordered;
  for (const auto& [name, total] : totals())
    ordered.emplace(total.first_seen, std::make_pair(name, total));
  std::string out = "stage                                  calls    total ms     mean us\n";
  char line[160];
  for (const auto& entry : ordered) {
    const auto& [name, total] = entry.second;
    std::snprintf(line, sizeof(line), "%-36s %8lld %11.3f %11.2f\n", name.c_str(),
                  static_cast<long long>(total.calls), total.nanoseconds * 1e-6,
                  total.calls > 0 ? total.nanoseconds * 1e-3 / total.calls : 0.0);
    out += line;
  }
  return out;
}

void StageProfiler::reset() {
  std::lock_guard<std::mutex> lock(totals_mutex());
  totals().clear();
}

StageProfiler::Scope::Scope(const char* algorithm, const Stream& stream)
    : algorithm_(algorithm),
      stream_(&stream),
      enabled_(StageProfiler::enabled()),
      synchronises_(enabled_ && StageProfiler::synchronises()) {
  if (enabled_) {
    if (synchronises_) stream_->synchronize();
    last_ns_ = now_ns();
  }
}

void StageProfiler::Scope::mark(const char* stage) {
  if (!enabled_) return;
  if (synchronises_) stream_->synchronize();
  const int64_t now = now_ns();
  StageProfiler::add(algorithm_, stage, now - last_ns_);
  last_ns_ = now;
}

}  // namespace covox
