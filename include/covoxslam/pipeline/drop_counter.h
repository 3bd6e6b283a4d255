#pragma once
// DropCounter: counts every dropped input of one kind and says when to log it, so a broken
// sensor cannot flood the log while the count stays exact: the first drop is logged, then at
// most one line per `log_interval_s`, which reports the drops it summarises.
#include <cstdint>
#include <string>

namespace covox {
namespace pipeline {

class DropCounter {
 public:
  explicit DropCounter(double log_interval_s = 5.0) : log_interval_s_(log_interval_s) {}

  // Counts one drop at time `now_s` (any monotonic clock); true when this one should be logged.
  bool count(double now_s) {
    ++total_;
    ++since_last_log_;
    if (total_ == 1 || now_s - last_log_s_ >= log_interval_s_) {
      last_log_s_ = now_s;
      logged_batch_ = since_last_log_;
      since_last_log_ = 0;
      return true;
    }
    return false;
  }
  int64_t total() const { return total_; }
  // How many drops the line just allowed by count() stands for (itself and the silent ones before).
  int64_t logged_batch() const { return logged_batch_; }
  void reset() { *this = DropCounter(log_interval_s_); }

 private:
  double log_interval_s_;
  int64_t total_ = 0;
  int64_t since_last_log_ = 0;
  int64_t logged_batch_ = 0;
  double last_log_s_ = 0.0;
};

}  // namespace pipeline
}  // namespace covox
