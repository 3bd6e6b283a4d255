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
  if (!std::isfinite(value))
    bad_parameter(name, "must be a finite number, got " + number_text(value));
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
    bad_parameter(name, "must be in [" + std::to_string(minimum) + ", " + std::to_string(maximum) +
                            "], got " + std::to_string(value));
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

namespace {

// One entry per parameter: its name and how it is read into a SlamConfig. The name list and the
// reading come from this one table, so a parameter cannot be listed without being read.
struct SlamParameter {
  const char* name;
  std::function<void(const ParameterSource&, SlamConfig*)> read;
};

// A text parameter parsed by the library's own parser (which names the accepted values).
template <class Field, class Parse>
SlamParameter text_parameter(const char* name, Field field, Parse parse) {
  return {name, [name, field, parse](const ParameterSource& source, SlamConfig* config) {
            std::string text;
            if (!source.get_text(name, &text)) return;
            try {
              *field(config) = parse(text);
            } catch (const Error& error) {
              bad_parameter(name, error.what());
            }
          }};
}

template <class Field>
SlamParameter number_parameter(const char* name, Field field,
                               std::function<std::string(double)> check) {
  return {name, [name, field, check](const ParameterSource& source, SlamConfig* config) {
            read_number(source, name, field(config), check);
          }};
}

template <class Field>
SlamParameter integer_parameter(const char* name, Field field, int64_t minimum,
                                int64_t maximum = std::numeric_limits<int64_t>::max()) {
  return {name, [name, field, minimum, maximum](const ParameterSource& source, SlamConfig* config) {
            read_integer(source, name, field(config), minimum, maximum);
          }};
}

template <class Field>
SlamParameter bool_parameter(const char* name, Field field) {
  return {name, [name, field](const ParameterSource& source, SlamConfig* config) {
            read_bool(source, name, field(config));
          }};
}

std::string in_unit_interval_open_closed(double v) {
  return v > 0.0 && v <= 1.0 ? "" : "must be in (0, 1]";
}
std::string in_unit_interval_closed(double v) {
  return v >= 0.0 && v <= 1.0 ? "" : "must be in [0, 1]";
}
std::string in_unit_interval_right_open(double v) {
  return v >= 0.0 && v < 1.0 ? "" : "must be in [0, 1)";
}
std::string in_open_unit_interval(double v) {
  return v > 0.0 && v < 1.0 ? "" : "must be in (0, 1)";
}
std::string angle_up_to_pi(double v) {
  return v > 0.0 && v <= 3.14159265358979323846 ? "" : "must be in (0, pi]";
}

backend::PcgPreconditioner parse_preconditioner(const std::string& text) {
  if (text == "odometry_chain") return backend::PcgPreconditioner::kOdometryChain;
  if (text == "block_jacobi") return backend::PcgPreconditioner::kBlockJacobi;
  throw Error("unknown preconditioner '" + text + "' (expected odometry_chain or block_jacobi)");
}

Device parse_device(const std::string& text) { return select_device(parse_device_request(text)); }

// Field accessors: SlamConfig* -> pointer to the member.
#define COVOX_FIELD(member) [](SlamConfig* c) { return &c->member; }

const std::vector<SlamParameter>& slam_parameters() {
  static const std::vector<SlamParameter> table = {
      text_parameter("device", COVOX_FIELD(device), parse_device),
      // Map.
      number_parameter("voxel_size_m", COVOX_FIELD(map.voxel_size_m), positive),
      {"voxels_per_side",
       [](const ParameterSource& source, SlamConfig* config) {
         read_integer(source, "voxels_per_side", &config->map.voxels_per_side, 8, 16);
         if (config->map.voxels_per_side != 8 && config->map.voxels_per_side != 16) {
           bad_parameter("voxels_per_side",
                         "must be 8 or 16, got " + std::to_string(config->map.voxels_per_side));
         }
       }},
      integer_parameter("block_table_initial_bucket_count",
                        COVOX_FIELD(map.block_table.initial_bucket_count), 1),
      number_parameter("block_table_max_load_factor", COVOX_FIELD(map.block_table.max_load_factor),
                       in_open_unit_interval),
      bool_parameter("block_table_allow_growth", COVOX_FIELD(map.block_table.allow_growth)),
      // TSDF integration (voxblox's names).
      text_parameter("integration_method", COVOX_FIELD(tsdf.method), parse_tsdf_integration_method),
      number_parameter("truncation_distance_m", COVOX_FIELD(tsdf.truncation_distance_m), positive),
      number_parameter("max_weight", COVOX_FIELD(tsdf.max_weight), positive),
      number_parameter("min_ray_length_m", COVOX_FIELD(tsdf.min_ray_length_m), non_negative),
      number_parameter("max_ray_length_m", COVOX_FIELD(tsdf.max_ray_length_m), positive),
      bool_parameter("voxel_carving_enabled", COVOX_FIELD(tsdf.voxel_carving_enabled)),
      bool_parameter("allow_clear", COVOX_FIELD(tsdf.allow_clear)),
      bool_parameter("use_const_weight", COVOX_FIELD(tsdf.use_const_weight)),
      bool_parameter("use_weight_dropoff", COVOX_FIELD(tsdf.use_weight_dropoff)),
      bool_parameter("use_sparsity_compensation_factor",
                     COVOX_FIELD(tsdf.use_sparsity_compensation_factor)),
      number_parameter("sparsity_compensation_factor",
                       COVOX_FIELD(tsdf.sparsity_compensation_factor), positive),
      bool_parameter("integrate_color", COVOX_FIELD(tsdf.integrate_color)),
      integer_parameter("fixed_point_sums_max_scratch_mb",
                        COVOX_FIELD(tsdf.fixed_point_sums_max_scratch_mb), 0, 1 << 20),
      // ESDF and mesh.
      number_parameter("esdf_max_distance_m", COVOX_FIELD(esdf.esdf_max_distance_m), positive),
      number_parameter("esdf_site_distance_threshold_vox",
                       COVOX_FIELD(esdf.site_distance_threshold_vox), positive),
      number_parameter("esdf_min_weight", COVOX_FIELD(esdf.min_weight), non_negative),
      integer_parameter("esdf_max_window_voxels", COVOX_FIELD(esdf.max_window_voxels), 1),
      number_parameter("mesh_min_weight", COVOX_FIELD(mesh.min_weight), non_negative),
      // Submaps.
      text_parameter("submap_creation_policy", COVOX_FIELD(submaps.policy),
                     parse_submap_creation_policy),
      number_parameter("submap_creation_interval_s", COVOX_FIELD(submaps.interval_s), positive),
      number_parameter("submap_creation_distance_m", COVOX_FIELD(submaps.distance_m), positive),
      integer_parameter("submap_max_blocks", COVOX_FIELD(submaps.max_blocks), 1),
      // Queues.
      integer_parameter("sensor_queue_size", COVOX_FIELD(sensor_queue_size), 1, 100000),
      integer_parameter("submap_queue_size", COVOX_FIELD(submap_queue_size), 1, 1000),
      // Pose graph and its solver.
      number_parameter("odometry_translation_sigma_m", COVOX_FIELD(odometry_translation_sigma_m),
                       positive),
      number_parameter("odometry_yaw_sigma_rad", COVOX_FIELD(odometry_yaw_sigma_rad), positive),
      integer_parameter("optimize_every_n_submaps", COVOX_FIELD(optimize_every_n_submaps), 0,
                        1000000),
      bool_parameter("interpolate_trajectory_correction",
                     COVOX_FIELD(interpolate_trajectory_correction)),
      number_parameter("external_stamp_tolerance_s", COVOX_FIELD(external_stamp_tolerance_s),
                       positive),
      integer_parameter("solver_max_iterations", COVOX_FIELD(solver.max_iterations), 1, 1000000),
      number_parameter("solver_function_tolerance", COVOX_FIELD(solver.function_tolerance),
                       positive),
      number_parameter("solver_gradient_tolerance", COVOX_FIELD(solver.gradient_tolerance),
                       positive),
      number_parameter("solver_parameter_tolerance", COVOX_FIELD(solver.parameter_tolerance),
                       positive),
      integer_parameter("solver_pcg_max_iterations", COVOX_FIELD(solver.pcg_max_iterations), 1,
                        1000000),
      number_parameter("solver_pcg_relative_tolerance", COVOX_FIELD(solver.pcg_relative_tolerance),
                       in_open_unit_interval),
      text_parameter("solver_preconditioner", COVOX_FIELD(solver.preconditioner),
                     parse_preconditioner),
      integer_parameter("solver_chain_segment_vertices", COVOX_FIELD(solver.chain_segment_vertices),
                        0, 1000000000),
      // Registration between overlapping submaps (voxgraph's names where it has them).
      bool_parameter("registration_enabled", COVOX_FIELD(registration.enabled)),
      text_parameter("registration_mode", COVOX_FIELD(registration.mode), parse_registration_mode),
      number_parameter("registration_sampling_ratio", COVOX_FIELD(registration.sampling_ratio),
                       in_unit_interval_open_closed),
      text_parameter("registration_distance", COVOX_FIELD(registration.distance),
                     parse_registration_distance),
      bool_parameter("registration_symmetric", COVOX_FIELD(registration.symmetric)),
      text_parameter("registration_robust_loss", COVOX_FIELD(registration.robust_loss),
                     parse_robust_loss),
      number_parameter("registration_robust_loss_scale_m",
                       COVOX_FIELD(registration.robust_loss_scale_m), positive),
      number_parameter("registration_point_sigma_m", COVOX_FIELD(registration.point_sigma_m),
                       positive),
      number_parameter("registration_min_sigma_m", COVOX_FIELD(registration.min_sigma_m),
                       non_negative),
      number_parameter("registration_min_sigma_yaw_rad",
                       COVOX_FIELD(registration.min_sigma_yaw_rad), non_negative),
      integer_parameter("registration_min_shared_blocks",
                        COVOX_FIELD(registration.min_shared_blocks), 1),
      integer_parameter("registration_min_points", COVOX_FIELD(registration.min_points), 4),
      number_parameter("registration_max_correction_m", COVOX_FIELD(registration.max_correction_m),
                       positive),
      number_parameter("registration_max_correction_rad",
                       COVOX_FIELD(registration.max_correction_rad), angle_up_to_pi),
      number_parameter("registration_inlier_distance_m",
                       COVOX_FIELD(registration.inlier_distance_m), positive),
      number_parameter("registration_min_inlier_fraction",
                       COVOX_FIELD(registration.min_inlier_fraction), in_unit_interval_closed),
      integer_parameter("registration_min_fit_points", COVOX_FIELD(registration.min_fit_points), 0),
      bool_parameter("registration_search_enabled", COVOX_FIELD(registration.search_enabled)),
      number_parameter("registration_search_step_m", COVOX_FIELD(registration.search_step_m),
                       positive),
      number_parameter("registration_search_step_rad", COVOX_FIELD(registration.search_step_rad),
                       positive),
      number_parameter("registration_search_max_yaw_rad",
                       COVOX_FIELD(registration.search_max_yaw_rad), non_negative),
      integer_parameter("registration_search_candidates",
                        COVOX_FIELD(registration.search_candidates), 1, 1000),
      integer_parameter("registration_search_max_points",
                        COVOX_FIELD(registration.search_max_points), 4),
      bool_parameter("registration_revisit_wall_search",
                     COVOX_FIELD(registration.revisit_wall_search)),
      integer_parameter("registration_revisit_min_id_gap",
                        COVOX_FIELD(registration.revisit_min_id_gap), 1,
                        std::numeric_limits<int64_t>::max()),
      number_parameter("registration_wall_search_range_m",
                       COVOX_FIELD(registration.wall_search_range_m), non_negative),
      number_parameter("registration_wall_search_min_score",
                       COVOX_FIELD(registration.wall_search_min_score), non_negative),
      number_parameter("registration_wall_search_min_jump_m",
                       COVOX_FIELD(registration.wall_search_min_jump_m), non_negative),
      integer_parameter("registration_max_partners", COVOX_FIELD(registration.max_partners), 0,
                        1000000),
      integer_parameter("registration_max_iterations", COVOX_FIELD(registration.max_iterations), 1,
                        1000000),
      integer_parameter("registration_coarse_levels", COVOX_FIELD(registration.coarse_levels), 0,
                        6),
      number_parameter("registration_max_graph_residual_m",
                       COVOX_FIELD(registration.max_graph_residual_m), non_negative),
      number_parameter("registration_gate_worst_fraction",
                       COVOX_FIELD(registration.gate_worst_fraction), in_unit_interval_right_open),
  };
  return table;
}

#undef COVOX_FIELD

}  // namespace

const std::vector<std::string>& slam_parameter_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> list;
    for (const SlamParameter& parameter : slam_parameters()) list.push_back(parameter.name);
    return list;
  }();
  return names;
}

void read_slam_config(const ParameterSource& source, SlamConfig* config) {
  for (const SlamParameter& parameter : slam_parameters()) parameter.read(source, config);
  // Relations between parameters, in the library's own words.
  try {
    validate(*config);
  } catch (const Error& error) {
    throw Error(std::string("parameters: ") + error.what());
  }
}

}  // namespace pipeline
}  // namespace covox
