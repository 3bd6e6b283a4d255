#pragma once
// How a TSDF frame merges its voxel visits, beyond what TsdfIntegratorConfig exposes: the
// shipped choice, and the switches the tests use to run every path on both backends and compare
// them (not user parameters).
//
// A frame merges the visits of each voxel in one of three ways (TsdfFramePlan, tsdf_frame_plan.h):
//   - every visit sorted by voxel key and reduced (the reference);
//   - free-space visits summed in fixed point as the rays are walked, only the band's sorted;
//   - every visit summed in fixed point (weight, distance, colour): no record at all.
// The fixed-point sums are exact integers, so the map is the same up to their rounding (2^-32 of
// a unit weight) whatever order the visits arrive in.
#include <cstdint>

namespace covox::integrators {

class TsdfIntegrator;

namespace tsdf {

// GPU frames with fewer voxel visits than this sort every visit rather than sum their free-space
// visits (the sums' extra pass is not paid back by the smaller sort).
constexpr int64_t kFreeSpaceSumsMinVisits = int64_t(1) << 20;

struct FrameStrategy {
  // Free-space visits may be summed in fixed point (false: every visit is sorted).
  bool sum_free_space_in_fixed_point = true;
  // With the above, the band's visits may be summed too, so that no visit is sorted.
  bool sum_band_in_fixed_point = true;
  // The GPU sums only free space for frames of at least this many visits (when every visit's sums
  // do not fit the scratch budget).
  int64_t free_space_sums_min_visits = kFreeSpaceSumsMinVisits;
  // The CPU twin takes the fixed-point paths too. Shipped: no, its dense grouping by block
  // (tsdf_group_updates_cpu.h) merges a block's visits about as cheaply and keeps to the caches.
  bool cpu_twin_sums_in_fixed_point = false;
};

// The strategy an integrator's frames follow (the shipped one until set).
class IntegratorInternals {
 public:
  static void set_strategy(TsdfIntegrator& integrator, const FrameStrategy& strategy);
  static const FrameStrategy& strategy(const TsdfIntegrator& integrator);
};

}  // namespace tsdf
}  // namespace covox::integrators
