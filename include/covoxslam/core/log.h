#pragma once
#include <functional>
#include <sstream>
#include <string>

namespace covox {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };

// The library never prints directly: it hands lines to a sink. The default sink writes to
// stderr; the ROS layer installs one that forwards to ROS_INFO/ROS_WARN, tests may capture.
using LogSink = std::function<void(LogLevel, const std::string&)>;

void set_log_sink(LogSink sink);
void set_min_log_level(LogLevel level);
void log_line(LogLevel level, const std::string& message);

namespace internal {
inline void append_all(std::ostringstream&) {}
template <class T, class... Rest>
void append_all(std::ostringstream& stream, const T& first, const Rest&... rest) {
  stream << first;
  append_all(stream, rest...);
}
}  // namespace internal

template <class... Parts>
void log_message(LogLevel level, const Parts&... parts) {
  std::ostringstream stream;
  internal::append_all(stream, parts...);
  log_line(level, stream.str());
}
template <class... Parts>
void log_info(const Parts&... parts) {
  log_message(LogLevel::kInfo, parts...);
}
template <class... Parts>
void log_warning(const Parts&... parts) {
  log_message(LogLevel::kWarning, parts...);
}
template <class... Parts>
void log_error(const Parts&... parts) {
  log_message(LogLevel::kError, parts...);
}

}  // namespace covox
