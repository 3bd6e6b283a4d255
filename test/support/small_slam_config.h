#pragma once
// The SlamConfig of the pipeline tests that scan a small hollow sphere: small and fast on 2 cores.
#include "covoxslam/pipeline/slam_system.h"

namespace covox {
namespace testing_support {

// The registration the pipeline tests were written for: one-way fine alignment from the
// odometry's guess within 2 m, no revisit start from the walls, no worst-first gate rounds, one
// trajectory correction per submap.
void use_one_way_registration(pipeline::SlamConfig* config);

// CPU; 0.2 m voxels in 8-voxel blocks, truncation 0.6 m, 8 m rays, ESDF up to 1 m; a new submap
// every second; queues deep enough that no scan is dropped for lack of room; one-way registration
// without the revisit aids, one trajectory correction per submap.
pipeline::SlamConfig small_slam_config();

}  // namespace testing_support
}  // namespace covox
