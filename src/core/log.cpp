#include "covoxslam/core/log.h"

#include <atomic>
#include <iostream>
#include <mutex>

namespace covox {
namespace {

const char* level_name(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarning:
      return "warning";
    case LogLevel::kError:
      return "error";
  }
  return "?";
}

std::mutex& sink_mutex() {
  static std::mutex mutex;
  return mutex;
}
LogSink& current_sink() {
  static LogSink sink = [](LogLevel level, const std::string& message) {
    std::cerr << "[covoxslam " << level_name(level) << "] " << message << std::endl;
  };
  return sink;
}
std::atomic<int>& min_level() {
  static std::atomic<int> level{static_cast<int>(LogLevel::kInfo)};
  return level;
}

}  // namespace

void set_log_sink(LogSink sink) {
  std::lock_guard<std::mutex> lock(sink_mutex());
  current_sink() = std::move(sink);
}

void set_min_log_level(LogLevel level) { min_level() = static_cast<int>(level); }

void log_line(LogLevel level, const std::string& message) {
  if (static_cast<int>(level) < min_level()) return;
  std::lock_guard<std::mutex> lock(sink_mutex());
  if (current_sink()) current_sink()(level, message);
}

}  // namespace covox
