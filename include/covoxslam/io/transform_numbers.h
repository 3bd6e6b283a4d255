#pragma once
// A rigid transform written as numbers, the way configuration files and command lines give a
// sensor's extrinsic (the nodelet's `ros.T_base_sensor`, voxgraph's `T_base_link_sensor`,
// `run_slam --extrinsic`): 7 numbers `x y z qx qy qz qw` (a translation in metres and a unit
// quaternion, the order of tf's static_transform_publisher) or 16, a row-major homogeneous 4x4
// matrix. T_base_sensor maps points of the sensor frame into the base frame.
#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace covox {
namespace io {

// Throws covox::Error "<what>: <problem>" for a count other than 7 or 16, a non-finite number, a
// quaternion off unit length by more than 1e-3 (a nearer one is normalised) or a 4x4 matrix that
// is not a rigid transform.
Eigen::Isometry3d transform_from_numbers(const std::vector<double>& values,
                                         const std::string& what);

// The same from text: the numbers separated by spaces and/or commas, optionally inside brackets
// ("0.03 0 0.08 0 0 1 0", "0.03,0,0.08,0,0,1,0" or a YAML flow list "[0.03, 0, 0.08, 0, 0, 1, 0]").
// Throws covox::Error naming `what` and the token that is not a number.
Eigen::Isometry3d transform_from_text(const std::string& text, const std::string& what);

// "x y z qx qy qz qw" of `T` (6 decimals; qw >= 0), for log lines.
std::string transform_to_text(const Eigen::Isometry3d& T);

}  // namespace io
}  // namespace covox
