#pragma once
// The sensor extrinsic of a bag run, taken the way the nodelet takes it, so that one configuration
// file maps a bag the same offline and through ROS: the `ros` section's `base_frame`,
// `use_tf_for_extrinsic` and `T_base_sensor` of the configuration files (in order; a later file's
// value wins), then the command line over them: `--base-frame F` and `--extrinsic "x y z qx qy qz
// qw"` (io/transform_numbers.h; giving it means use_tf_for_extrinsic: false). Without an
// extrinsic from either, the bag's tf connects the odometry frame to the clouds' frame.
#include <string>
#include <vector>

#include "runner/bag_scan_source.h"

namespace covox {
namespace tools {

// Sets options->base_frame, T_base_sensor and extrinsic_origin. Empty option texts were not
// given. Throws covox::Error naming the file and line or the option for a bad value.
void resolve_bag_extrinsic(const std::vector<std::string>& config_paths,
                           const std::string& base_frame_option,
                           const std::string& extrinsic_option, BagScanOptions* options);

}  // namespace tools
}  // namespace covox
