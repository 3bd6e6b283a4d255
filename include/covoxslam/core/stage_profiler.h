#pragma once
// Opt-in wall-clock breakdown of a multi-stage GPU algorithm, for finding where a frame's time
// goes without Nsight Systems. Enabled by COVOX_PROFILE_STAGES=1 (read once); disabled, mark() is
// one branch. Enabled, mark() synchronises the stream and charges the wall time since the
// previous mark (or the scope's start) to the named stage, kernels, host work and waits alike;
// the synchronisations slow the whole a little, so read the shares, not the sum.
// COVOX_PROFILE_STAGES=host charges the host's time between marks without synchronising (its
// launches, its own work and the code's own waits, the GPU running ahead as unprofiled); each
// mark costs the host a lookup under a lock, so every stage reads high by that much.
#include <cstdint>
#include <string>

#include "covoxslam/core/stream.h"

namespace covox {

// Usage (the integrators do this; the TSDF frame's labels are its stages' numbers and names,
// docs/design.md):
//   StageProfiler::Scope profile("tsdf", stream);   // begin
//   ...; profile.mark("1 rays: merge + tally"); ...; profile.mark("2b walk: traverse");
// and a tool prints StageProfiler::report() at the end.
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
