#pragma once
// Opt-in wall-clock breakdown of a multi-stage GPU algorithm, for finding where a frame's time
// goes on a machine without Nsight Systems. Enabled by the environment variable
// COVOX_PROFILE_STAGES=1 (read once); when disabled, mark() is one branch and costs nothing else.
//
// When enabled, mark() synchronises the stream and charges the wall time since the previous mark
// (or since begin()) to the named stage, so each stage's figure holds its kernels, its host work
// and its own synchronisations. The synchronisations themselves slow the whole down a little:
// read the table for the shares, not the absolute sum.
// COVOX_PROFILE_STAGES=host charges the host's time between marks without synchronising: where
// the host spends a frame (its launches, its own work and the waits the code itself does), with
// the GPU running ahead as it does unprofiled. Each mark costs the host a lookup under a lock,
// so every stage reads high by that much.
//
// Usage (the integrators do this):
//   StageProfiler::Scope profile("tsdf", stream);   // begin
//   ...; profile.mark("rays"); ...; profile.mark("sort");
// and a tool prints StageProfiler::report() at the end.
#include <cstdint>
#include <string>

#include "covoxslam/core/stream.h"

namespace covox {

class StageProfiler {
 public:
  static bool enabled();
  static bool synchronises();  // false for COVOX_PROFILE_STAGES=host
  // Totals of every stage seen so far, as a table ("algorithm/stage  calls  total ms  mean us").
  static std::string report();
  static void reset();

  class Scope {
   public:
    Scope(const char* algorithm, const Stream& stream);
    void mark(const char* stage);

   private:
    const char* algorithm_;
    const Stream* stream_;
    bool enabled_;
    bool synchronises_;
    int64_t last_ns_ = 0;
  };

 private:
  static void add(const char* algorithm, const char* stage, int64_t nanoseconds);
};

}  // namespace covox
