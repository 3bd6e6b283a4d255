#include "covoxslam/pipeline/slam_parameters.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <limits>
#include <sstream>

#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"

namespace covox {
namespace pipeline {

namespace {

[[noreturn]] void bad_parameter(const std::string& name, const std::string& problem) {
  throw Error("parameter '" + name + "': " + problem);
}

std::string number_text(double value) {
  std::ostringstream stream;
  stream << value;
  return stream.str();
}

// Reads a number when set; `check` returns an empty string when the value is acceptable.
template <class T>
void read_number(const ParameterSource& source, const std::string& name, T* field,
                 const std::function<std::string(double)>& check) {
  double value = 0.0;
  if (!source.get_number(name, &value)) return;
  if (!std::isfinite(value)) bad_parameter(name, "must be a finite number, got " + number_text(value));
  const std::string problem = check(value);
  if (!problem.empty()) bad_parameter(name, problem + ", got " + number_text(value));
  *field = static_cast<T>(value);
}

template <class T>
void read_integer(const ParameterSource& source, const std::string& name, T* field, int64_t minimum,
                  int64_t maximum = std::numeric_limits<int64_t>::max()) {
  int64_t value = 0;
  if (!source.get_integer(name, &value)) return;
  if (value < minimum || value > maximum) {
    bad_parameter(name, "must be in [" + std::to_string(minimum) + ", " + std::to_string(maximum) + "], got " +
                            std::to_string(value));
  }
  *field = static_cast<T>(value);
}

void read_bool(const ParameterSource& source, const std::string& name, bool* field) {
  bool value = false;
  if (source.get_bool(name, &value)) *field = value;
}

std::string positive(double value) { return value > 0.0 ? "" : "must be positive"; }
std::string non_negative(double value) { return value >= 0.0 ? "" : "must be >= 0"; }

}  // namespace

bool TextParameterSource::get_number(const std::string& name, double* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  char* end = nullptr;
  errno = 0;
  const double parsed = std::strtod(it->second.c_str(), &end);
  if (it->second.empty() || *end != '\0' || errno == ERANGE) {
    bad_parameter(name, "expected a number, got '" + it->second + "'");
  }
  *value = parsed;
  return true;
}

bool TextParameterSource::get_integer(const std::string& name, int64_t* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  char* end = nullptr;
  errno = 0;
  const long long parsed = std::strtoll(it->second.c_str(), &end, 10);
  if (it->second.empty() || *end != '\0' || errno == ERANGE) {
    bad_parameter(name, "expected an integer, got '" + it->second + "'");
  }
  *value = parsed;
  return true;
}

bool TextParameterSource::get_bool(const std::string& name, bool* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  if (it->second == "true") {
    *value = true;
  } else if (it->second == "false") {
    *value = false;
  } else {
    bad_parameter(name, "expected true or false, got '" + it->second + "'");
  }
  return true;
}

bool TextParameterSource::get_text(const std::string& name, std::string* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  *value = it->second;
  return true;
}

const std::vector<std::string>& slam_parameter_names() {
  static const std::vector<std::string> names = {
      "device", "voxel_size_m", "voxels_per_side", "block_table_initial_bucket_count",
      "block_table_max_load_factor", "block_table_allow_growth", "integration_method", "truncation_distance_m",
      "max_weight", "min_ray_length_m", "max_ray_length_m", "voxel_carving_enabled", "allow_clear",
      "use_const_weight", "use_weight_dropoff", "use_sparsity_compensation_factor", "sparsity_compensation_factor",
      "integrate_color", "esdf_max_distance_m", "esdf_site_distance_threshold_vox", "esdf_min_weight",
      "mesh_min_weight", "submap_creation_policy", "submap_creation_interval_s", "submap_creation_distance_m",
      "submap_max_blocks", "sensor_queue_size", "submap_queue_size", "odometry_translation_sigma_m",
      "odometry_yaw_sigma_rad", "optimize_every_n_submaps", "solver_max_iterations", "solver_function_tolerance",
      "solver_pcg_max_iterations", "solver_pcg_relative_tolerance", "registration_enabled",
      "registration_sampling_ratio", "registration_distance", "registration_robust_loss",
      "registration_robust_loss_scale_m", "registration_point_sigma_m", "registration_min_shared_blocks",
      "registration_min_points", "registration_max_correction_m", "registration_max_correction_rad",
      "registration_max_partners", "registration_max_iterations", "external_stamp_tolerance_s"};
  return names;
}

void read_slam_config(const ParameterSource& source, SlamConfig* config) {
  std::string text;
  if (source.get_text("device", &text)) {
    try {
      config->device = select_device(parse_device_request(text));
    } catch (const Error& error) {
      bad_parameter("device", error.what());
    }
  }
  // Map.
  read_number(source, "voxel_size_m", &config->map.voxel_size_m, positive);
  read_integer(source, "voxels_per_side", &config->map.voxels_per_side, 8, 16);
  if (config->map.voxels_per_side != 8 && config->map.voxels_per_side != 16) {
    bad_parameter("voxels_per_side", "must be 8 or 16, got " + std::to_string(config->map.voxels_per_side));
  }
  read_integer(source, "block_table_initial_bucket_count", &config->map.block_table.initial_bucket_count, 1);
  read_number(source, "block_table_max_load_factor", &config->map.block_table.max_load_factor,
              [](double v) { return v > 0.0 && v < 1.0 ? "" : "must be in (0, 1)"; });
  read_bool(source, "block_table_allow_growth", &config->map.block_table.allow_growth);
  // TSDF integration (voxblox's names).
  if (source.get_text("integration_method", &text)) {
    try {
      config->tsdf.method = parse_tsdf_integration_method(text);
    } catch (const Error& error) {
      bad_parameter("integration_method", error.what());
    }
  }
  read_number(source, "truncation_distance_m", &config->tsdf.truncation_distance_m, positive);
  read_number(source, "max_weight", &config->tsdf.max_weight, positive);
  read_number(source, "min_ray_length_m", &config->tsdf.min_ray_length_m, non_negative);
  read_number(source, "max_ray_length_m", &config->tsdf.max_ray_length_m, positive);
  read_bool(source, "voxel_carving_enabled", &config->tsdf.voxel_carving_enabled);
  read_bool(source, "allow_clear", &config->tsdf.allow_clear);
  read_bool(source, "use_const_weight", &config->tsdf.use_const_weight);
  read_bool(source, "use_weight_dropoff", &config->tsdf.use_weight_dropoff);
  read_bool(source, "use_sparsity_compensation_factor", &config->tsdf.use_sparsity_compensation_factor);
  read_number(source, "sparsity_compensation_factor", &config->tsdf.sparsity_compensation_factor, positive);
  read_bool(source, "integrate_color", &config->tsdf.integrate_color);
  // ESDF and mesh.
  read_number(source, "esdf_max_distance_m", &config->esdf.esdf_max_distance_m, positive);
  read_number(source, "esdf_site_distance_threshold_vox", &config->esdf.site_distance_threshold_vox, positive);
  read_number(source, "esdf_min_weight", &config->esdf.min_weight, non_negative);
  read_number(source, "mesh_min_weight", &config->mesh.min_weight, non_negative);
  // Submaps.
  if (source.get_text("submap_creation_policy", &text)) {
    try {
      config->submaps.policy = parse_submap_creation_policy(text);
    } catch (const Error& error) {
      bad_parameter("submap_creation_policy", error.what());
    }
  }
  read_number(source, "submap_creation_interval_s", &config->submaps.interval_s, positive);
  read_number(source, "submap_creation_distance_m", &config->submaps.distance_m, positive);
  read_integer(source, "submap_max_blocks", &config->submaps.max_blocks, 1);
  // Queues and backend.
  read_integer(source, "sensor_queue_size", &config->sensor_queue_size, 1, 100000);
  read_integer(source, "submap_queue_size", &config->submap_queue_size, 1, 1000);
  read_number(source, "odometry_translation_sigma_m", &config->odometry_translation_sigma_m, positive);
  read_number(source, "odometry_yaw_sigma_rad", &config->odometry_yaw_sigma_rad, positive);
  read_integer(source, "optimize_every_n_submaps", &config->optimize_every_n_submaps, 0, 1000000);
  read_integer(source, "solver_max_iterations", &config->solver.max_iterations, 1, 1000000);
  read_number(source, "solver_function_tolerance", &config->solver.function_tolerance, positive);
  read_integer(source, "solver_pcg_max_iterations", &config->solver.pcg_max_iterations, 1, 1000000);
  read_number(source, "solver_pcg_relative_tolerance", &config->solver.pcg_relative_tolerance, positive);

  // Registration between overlapping submaps (voxgraph's names where it has them).
  SubmapRegistrationConfig& registration = config->registration;
  read_bool(source, "registration_enabled", &registration.enabled);
  read_number(source, "registration_sampling_ratio", &registration.sampling_ratio,
              [](double v) { return v > 0.0 && v <= 1.0 ? "" : "must be in (0, 1]"; });
  if (source.get_text("registration_distance", &text)) {
    try {
      registration.distance = parse_registration_distance(text);
    } catch (const Error& error) {
      bad_parameter("registration_distance", error.what());
    }
  }
  if (source.get_text("registration_robust_loss", &text)) {
    try {
      registration.robust_loss = parse_robust_loss(text);
    } catch (const Error& error) {
      bad_parameter("registration_robust_loss", error.what());
    }
  }
  read_number(source, "registration_robust_loss_scale_m", &registration.robust_loss_scale_m, positive);
  read_number(source, "registration_point_sigma_m", &registration.point_sigma_m, positive);
  read_integer(source, "registration_min_shared_blocks", &registration.min_shared_blocks, 1);
  read_integer(source, "registration_min_points", &registration.min_points, 1);
  read_number(source, "registration_max_correction_m", &registration.max_correction_m, positive);
  read_number(source, "registration_max_correction_rad", &registration.max_correction_rad, positive);
  read_integer(source, "registration_max_partners", &registration.max_partners, 0, 1000000);
  read_integer(source, "registration_max_iterations", &registration.max_iterations, 1, 1000000);
  read_number(source, "external_stamp_tolerance_s", &config->external_stamp_tolerance_s, positive);

  // Relations between parameters, in the library's own words.
  try {
    validate(*config);
  } catch (const Error& error) {
    throw Error(std::string("parameters: ") + error.what());
  }
}

}  // namespace pipeline
}  // namespace covox
