#include "covoxslam/pipeline/slam_parameters.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <limits>
#include <sstream>

#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/setting_values.h"

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

// The three readers share io/setting_values.h with the command line and the ROS parameters, so
// a value reads the same wherever it is written.
bool TextParameterSource::get_number(const std::string& name, double* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  const std::string problem = io::parse_number_value(it->second, value);
  if (!problem.empty()) bad_parameter(name, problem);
  return true;
}

bool TextParameterSource::get_integer(const std::string& name, int64_t* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  const std::string problem = io::parse_integer_value(it->second, value);
  if (!problem.empty()) bad_parameter(name, problem);
  return true;
}

bool TextParameterSource::get_bool(const std::string& name, bool* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  const std::string problem = io::parse_bool_value(it->second, value);
  if (!problem.empty()) bad_parameter(name, problem);
  return true;
}

bool TextParameterSource::get_text(const std::string& name, std::string* value) const {
  auto it = values_.find(name);
  if (it == values_.end()) return false;
  *value = it->second;
  return true;
}

std::string TextParameterSource::location(const std::string& name) const {
  auto it = locations_.find(name);
  return it == locations_.end() ? std::string() : it->second;
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

void read_voxels_per_side(const ParameterSource& source, SlamConfig* config) {
  read_integer(source, "map.voxels_per_side", &config->map.voxels_per_side, 8, 16);
  if (config->map.voxels_per_side != 8 && config->map.voxels_per_side != 16) {
    bad_parameter("map.voxels_per_side",
                  "must be 8 or 16, got " + std::to_string(config->map.voxels_per_side));
  }
}

void add_map_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          text_parameter("device", COVOX_FIELD(device), parse_device),
          number_parameter("map.voxel_size_m", COVOX_FIELD(map.voxel_size_m), positive),
          {"map.voxels_per_side", read_voxels_per_side},
          integer_parameter("map.block_table.initial_bucket_count",
                            COVOX_FIELD(map.block_table.initial_bucket_count), 2),
          number_parameter("map.block_table.max_load_factor",
                           COVOX_FIELD(map.block_table.max_load_factor), in_open_unit_interval),
          bool_parameter("map.block_table.allow_growth", COVOX_FIELD(map.block_table.allow_growth)),
      });
}

// TSDF integration (voxblox's names).
void add_tsdf_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          text_parameter("tsdf.method", COVOX_FIELD(tsdf.method),
                         integrators::parse_tsdf_integration_method),
          number_parameter("tsdf.truncation_distance_m", COVOX_FIELD(tsdf.truncation_distance_m),
                           positive),
          number_parameter("tsdf.max_weight", COVOX_FIELD(tsdf.max_weight), positive),
          number_parameter("tsdf.min_ray_length_m", COVOX_FIELD(tsdf.min_ray_length_m),
                           non_negative),
          number_parameter("tsdf.max_ray_length_m", COVOX_FIELD(tsdf.max_ray_length_m), positive),
          bool_parameter("tsdf.voxel_carving_enabled", COVOX_FIELD(tsdf.voxel_carving_enabled)),
          bool_parameter("tsdf.allow_clear", COVOX_FIELD(tsdf.allow_clear)),
          bool_parameter("tsdf.use_const_weight", COVOX_FIELD(tsdf.use_const_weight)),
          bool_parameter("tsdf.use_weight_dropoff", COVOX_FIELD(tsdf.use_weight_dropoff)),
          bool_parameter("tsdf.use_sparsity_compensation_factor",
                         COVOX_FIELD(tsdf.use_sparsity_compensation_factor)),
          number_parameter("tsdf.sparsity_compensation_factor",
                           COVOX_FIELD(tsdf.sparsity_compensation_factor), positive),
          bool_parameter("tsdf.integrate_color", COVOX_FIELD(tsdf.integrate_color)),
          integer_parameter("tsdf.fixed_point_sums_max_scratch_mb",
                            COVOX_FIELD(tsdf.fixed_point_sums_max_scratch_mb), 0, 1 << 20),
      });
}

// ESDF, mesh, submaps, queues and the memory budget.
void add_esdf_mesh_submap_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          number_parameter("esdf.max_distance_m", COVOX_FIELD(esdf.esdf_max_distance_m), positive),
          number_parameter("esdf.site_distance_threshold_vox",
                           COVOX_FIELD(esdf.site_distance_threshold_vox), positive),
          number_parameter("esdf.min_weight", COVOX_FIELD(esdf.min_weight), non_negative),
          integer_parameter("esdf.max_window_voxels", COVOX_FIELD(esdf.max_window_voxels), 1),
          number_parameter("mesh.min_weight", COVOX_FIELD(mesh.min_weight), non_negative),
          text_parameter("submaps.policy", COVOX_FIELD(submaps.policy),
                         parse_submap_creation_policy),
          bool_parameter("deskew.enabled", COVOX_FIELD(deskew.enabled)),
          number_parameter("deskew.sweep_duration_s", COVOX_FIELD(deskew.sweep_duration_s),
                           positive),
          number_parameter("submaps.interval_s", COVOX_FIELD(submaps.interval_s), positive),
          number_parameter("submaps.distance_m", COVOX_FIELD(submaps.distance_m), positive),
          integer_parameter("submaps.max_blocks", COVOX_FIELD(submaps.max_blocks), 1),
          integer_parameter("queues.sensor_scans", COVOX_FIELD(sensor_queue_size), 1, 100000),
          integer_parameter("queues.submaps", COVOX_FIELD(submap_queue_size), 1, 1000),
          bool_parameter("queues.wait_when_full", COVOX_FIELD(wait_when_queues_full)),
          number_parameter("memory.device_budget_mb", COVOX_FIELD(memory.device_budget_mb),
                           non_negative),
          number_parameter("memory.host_budget_mb", COVOX_FIELD(memory.host_budget_mb),
                           non_negative),
          number_parameter("memory.device_cache_mb", COVOX_FIELD(memory.device_cache_mb),
                           non_negative),
          text_parameter("memory.spill_directory", COVOX_FIELD(memory.spill_directory),
                         [](const std::string& text) { return text; }),
      });
}

// The pose graph and its solver.
void add_pose_graph_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          number_parameter("pose_graph.odometry_translation_sigma_vox",
                           COVOX_FIELD(odometry_translation_sigma_vox), positive),
          number_parameter("pose_graph.odometry_yaw_sigma_rad", COVOX_FIELD(odometry_yaw_sigma_rad),
                           positive),
          number_parameter("pose_graph.odometry_drift_m_per_m", COVOX_FIELD(odometry_drift_m_per_m),
                           non_negative),
          number_parameter("pose_graph.odometry_drift_deg_per_m",
                           COVOX_FIELD(odometry_drift_deg_per_m), non_negative),
          bool_parameter("pose_graph.estimate_odometry_noise",
                         COVOX_FIELD(estimate_odometry_noise)),
          number_parameter("pose_graph.min_odometry_drift_m_per_m",
                           COVOX_FIELD(min_odometry_drift_m_per_m), positive),
          number_parameter("pose_graph.min_odometry_drift_deg_per_m",
                           COVOX_FIELD(min_odometry_drift_deg_per_m), positive),
          number_parameter("pose_graph.revisit_drift_min_path_m",
                           COVOX_FIELD(revisit_drift_min_path_m), non_negative),
          number_parameter("pose_graph.registration_loss_scale_sigmas",
                           COVOX_FIELD(registration_loss_scale_sigmas), non_negative),
          integer_parameter("pose_graph.optimize_every_n_submaps",
                            COVOX_FIELD(optimize_every_n_submaps), 0, 1000000),
          number_parameter("pose_graph.optimize_spacing_fraction",
                           COVOX_FIELD(optimize_spacing_fraction), non_negative),
          integer_parameter("pose_graph.max_solves_per_new_submap",
                            COVOX_FIELD(max_solves_per_new_submap), 1, 1000000),
          bool_parameter("pose_graph.interpolate_trajectory_correction",
                         COVOX_FIELD(interpolate_trajectory_correction)),
          number_parameter("pose_graph.external_stamp_tolerance_s",
                           COVOX_FIELD(external_stamp_tolerance_s), positive),
          integer_parameter("solver.max_iterations", COVOX_FIELD(solver.max_iterations), 1,
                            1000000),
          number_parameter("solver.function_tolerance", COVOX_FIELD(solver.function_tolerance),
                           positive),
          number_parameter("solver.gradient_tolerance", COVOX_FIELD(solver.gradient_tolerance),
                           positive),
          number_parameter("solver.parameter_tolerance", COVOX_FIELD(solver.parameter_tolerance),
                           positive),
          integer_parameter("solver.pcg_max_iterations", COVOX_FIELD(solver.pcg_max_iterations), 1,
                            1000000),
          number_parameter("solver.pcg_relative_tolerance",
                           COVOX_FIELD(solver.pcg_relative_tolerance), in_open_unit_interval),
          text_parameter("solver.preconditioner", COVOX_FIELD(solver.preconditioner),
                         parse_preconditioner),
          integer_parameter("solver.chain_segment_vertices",
                            COVOX_FIELD(solver.chain_segment_vertices), 0, 1000000000),
      });
}

// Registration between overlapping submaps: what is aligned, and how.
void add_registration_alignment_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          bool_parameter("registration.enabled", COVOX_FIELD(registration.enabled)),
          text_parameter("registration.mode", COVOX_FIELD(registration.mode),
                         parse_registration_mode),
          integer_parameter("registration.overlap.min_shared_blocks",
                            COVOX_FIELD(registration.overlap.min_shared_blocks), 1),
          integer_parameter("registration.overlap.max_partners",
                            COVOX_FIELD(registration.overlap.max_partners), 0, 1000000),
          integer_parameter("registration.overlap.max_visits",
                            COVOX_FIELD(registration.overlap.max_visits), 0, 1000000),
          number_parameter("registration.sampling.ratio", COVOX_FIELD(registration.sampling.ratio),
                           in_unit_interval_open_closed),
          text_parameter("registration.alignment.distance",
                         COVOX_FIELD(registration.alignment.distance), parse_registration_distance),
          bool_parameter("registration.alignment.symmetric",
                         COVOX_FIELD(registration.alignment.symmetric)),
          text_parameter("registration.alignment.robust_loss",
                         COVOX_FIELD(registration.alignment.robust_loss), parse_robust_loss),
          number_parameter("registration.alignment.robust_loss_scale_m",
                           COVOX_FIELD(registration.alignment.robust_loss_scale_m), positive),
          integer_parameter("registration.alignment.max_iterations",
                            COVOX_FIELD(registration.alignment.max_iterations), 1, 1000000),
          integer_parameter("registration.alignment.coarse_levels",
                            COVOX_FIELD(registration.alignment.coarse_levels), 0, 6),
      });
}

// Registration: which alignments become constraints, with what information.
void add_registration_constraint_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          integer_parameter("registration.acceptance.min_points",
                            COVOX_FIELD(registration.acceptance.min_points), 4),
          number_parameter("registration.acceptance.max_correction_m",
                           COVOX_FIELD(registration.acceptance.max_correction_m), positive),
          number_parameter("registration.acceptance.max_correction_rad",
                           COVOX_FIELD(registration.acceptance.max_correction_rad), angle_up_to_pi),
          number_parameter("registration.acceptance.max_residual_rms_vox",
                           COVOX_FIELD(registration.acceptance.max_residual_rms_vox), non_negative),
          number_parameter("registration.information.point_sigma_m",
                           COVOX_FIELD(registration.information.point_sigma_m), positive),
          number_parameter("registration.information.min_sigma_vox",
                           COVOX_FIELD(registration.information.min_sigma_vox), non_negative),
          number_parameter("registration.information.min_sigma_yaw_rad",
                           COVOX_FIELD(registration.information.min_sigma_yaw_rad), non_negative),
          bool_parameter("registration.revisits.wall_search",
                         COVOX_FIELD(registration.revisits.wall_search)),
          integer_parameter("registration.revisits.min_id_gap",
                            COVOX_FIELD(registration.revisits.min_id_gap), 1),
          number_parameter("registration.revisits.wall_search_range_m",
                           COVOX_FIELD(registration.revisits.wall_search_range_m), non_negative),
          number_parameter("registration.revisits.wall_search_min_score",
                           COVOX_FIELD(registration.revisits.wall_search_min_score), non_negative),
          number_parameter("registration.revisits.wall_search_min_jump_m",
                           COVOX_FIELD(registration.revisits.wall_search_min_jump_m), non_negative),
          number_parameter("registration.gate.max_residual_vox",
                           COVOX_FIELD(registration.gate.max_residual_vox), non_negative),
          number_parameter("registration.verification.max_mahalanobis_sq",
                           COVOX_FIELD(registration.verification.max_mahalanobis_sq), non_negative),
          number_parameter("registration.gate.worst_fraction",
                           COVOX_FIELD(registration.gate.worst_fraction),
                           in_unit_interval_right_open),
      });
}

std::string in_closed_unit_interval(double v) {
  return v >= 0.0 && v <= 1.0 ? "" : "must be in [0, 1]";
}

// Place recognition over finished submaps (pipeline/place_recognition.h).
void add_place_recognition_parameters(std::vector<SlamParameter>* table) {
  table->insert(
      table->end(),
      {
          bool_parameter("place_recognition.enabled", COVOX_FIELD(place_recognition.enabled)),
          integer_parameter("place_recognition.rings", COVOX_FIELD(place_recognition.rings), 1,
                            200),
          integer_parameter("place_recognition.sectors", COVOX_FIELD(place_recognition.sectors), 4,
                            720),
          number_parameter("place_recognition.max_radius_m",
                           COVOX_FIELD(place_recognition.max_radius_m), positive),
          integer_parameter("place_recognition.candidates",
                            COVOX_FIELD(place_recognition.candidates), 1, 1000),
          number_parameter("place_recognition.anchor_spacing_m",
                           COVOX_FIELD(place_recognition.anchor_spacing_m), non_negative),
          integer_parameter("place_recognition.exclude_recent_submaps",
                            COVOX_FIELD(place_recognition.exclude_recent_submaps), 0, 1000000),
          number_parameter("place_recognition.max_descriptor_distance",
                           COVOX_FIELD(place_recognition.max_descriptor_distance),
                           in_closed_unit_interval),
          number_parameter("place_recognition.translation_search_m",
                           COVOX_FIELD(place_recognition.translation_search_m), non_negative),
          number_parameter("place_recognition.min_overlap_score",
                           COVOX_FIELD(place_recognition.min_overlap_score),
                           in_closed_unit_interval),
          number_parameter("place_recognition.max_residual_rms_vox",
                           COVOX_FIELD(place_recognition.max_residual_rms_vox), positive),
          number_parameter("place_recognition.odometry_drift_m_per_m",
                           COVOX_FIELD(place_recognition.odometry_drift_m_per_m), non_negative),
          number_parameter("place_recognition.odometry_drift_deg_per_m",
                           COVOX_FIELD(place_recognition.odometry_drift_deg_per_m), non_negative),
          integer_parameter("place_recognition.confirm_window_submaps",
                            COVOX_FIELD(place_recognition.confirm_window_submaps), 1, 1000000),
          number_parameter("place_recognition.confirm_tolerance_m",
                           COVOX_FIELD(place_recognition.confirm_tolerance_m), positive),
          number_parameter("place_recognition.confirm_tolerance_deg",
                           COVOX_FIELD(place_recognition.confirm_tolerance_deg), positive),
          number_parameter("place_recognition.max_odometry_mahalanobis_sq",
                           COVOX_FIELD(place_recognition.max_odometry_mahalanobis_sq),
                           non_negative),
      });
}

const std::vector<SlamParameter>& slam_parameters() {
  static const std::vector<SlamParameter> table = [] {
    std::vector<SlamParameter> all;
    add_map_parameters(&all);
    add_tsdf_parameters(&all);
    add_esdf_mesh_submap_parameters(&all);
    add_pose_graph_parameters(&all);
    add_registration_alignment_parameters(&all);
    add_registration_constraint_parameters(&all);
    add_place_recognition_parameters(&all);
    return all;
  }();
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
  for (const SlamParameter& parameter : slam_parameters()) {
    try {
      parameter.read(source, config);
    } catch (const Error& error) {
      const std::string where = source.location(parameter.name);
      if (where.empty()) throw;
      throw Error(where + ": " + error.what());
    }
  }
  // Relations between parameters, in the library's own words.
  try {
    validate(*config);
  } catch (const Error& error) {
    throw Error(std::string("parameters: ") + error.what());
  }
}

}  // namespace pipeline
}  // namespace covox
