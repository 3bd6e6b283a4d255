// Every SLAM parameter name reaches its SlamConfig field, and the shipped parameter files and the
// ROS documentation list every one of them: a field added to SlamConfig (registration, solver)
// and made readable must also be documented, and a name in config/*.yaml must be readable.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "support/parameter_errors.h"
#include "flat_yaml.h"
#include "slam_run.h"

namespace covox {
namespace pipeline {
namespace {

namespace fs = std::filesystem;

// The repository root, from this file's path (CMake compiles sources by absolute path).
fs::path repository_root() { return fs::path(__FILE__).parent_path().parent_path(); }

struct Expectation {
  std::string value;                             // a valid, non-default value
  std::function<bool(const SlamConfig&)> holds;  // the field took it
};

// The reference: each name with the field it must set, written independently of the reader's table.
std::map<std::string, Expectation> expectations() {
  using backend::PcgPreconditioner;
  using backend::RegistrationDistance;
  using backend::RobustLoss;
  return {
      {"device", {"cpu", [](const SlamConfig& c) { return c.device == Device::kCpu; }}},
      {"voxel_size_m", {"0.15", [](const SlamConfig& c) { return c.map.voxel_size_m == 0.15f; }}},
      {"voxels_per_side", {"8", [](const SlamConfig& c) { return c.map.voxels_per_side == 8; }}},
      {"block_table_initial_bucket_count",
       {"1234",
        [](const SlamConfig& c) { return c.map.block_table.initial_bucket_count == 1234u; }}},
      {"block_table_max_load_factor",
       {"0.5", [](const SlamConfig& c) { return c.map.block_table.max_load_factor == 0.5; }}},
      {"block_table_allow_growth",
       {"false", [](const SlamConfig& c) { return !c.map.block_table.allow_growth; }}},
      {"integration_method",
       {"simple",
        [](const SlamConfig& c) { return c.tsdf.method == TsdfIntegrationMethod::kSimple; }}},
      {"truncation_distance_m",
       {"0.45", [](const SlamConfig& c) { return c.tsdf.truncation_distance_m == 0.45f; }}},
      {"max_weight", {"77", [](const SlamConfig& c) { return c.tsdf.max_weight == 77.0f; }}},
      {"min_ray_length_m",
       {"0.3", [](const SlamConfig& c) { return c.tsdf.min_ray_length_m == 0.3f; }}},
      {"max_ray_length_m",
       {"12.5", [](const SlamConfig& c) { return c.tsdf.max_ray_length_m == 12.5f; }}},
      {"voxel_carving_enabled",
       {"false", [](const SlamConfig& c) { return !c.tsdf.voxel_carving_enabled; }}},
      {"allow_clear", {"false", [](const SlamConfig& c) { return !c.tsdf.allow_clear; }}},
      {"use_const_weight", {"true", [](const SlamConfig& c) { return c.tsdf.use_const_weight; }}},
      {"use_weight_dropoff",
       {"false", [](const SlamConfig& c) { return !c.tsdf.use_weight_dropoff; }}},
      {"use_sparsity_compensation_factor",
       {"true", [](const SlamConfig& c) { return c.tsdf.use_sparsity_compensation_factor; }}},
      {"sparsity_compensation_factor",
       {"20", [](const SlamConfig& c) { return c.tsdf.sparsity_compensation_factor == 20.0f; }}},
      {"integrate_color", {"false", [](const SlamConfig& c) { return !c.tsdf.integrate_color; }}},
      {"fixed_point_sums_max_scratch_mb",
       {"64", [](const SlamConfig& c) { return c.tsdf.fixed_point_sums_max_scratch_mb == 64; }}},
      {"esdf_max_distance_m",
       {"3", [](const SlamConfig& c) { return c.esdf.esdf_max_distance_m == 3.0f; }}},
      {"esdf_site_distance_threshold_vox",
       {"1.5", [](const SlamConfig& c) { return c.esdf.site_distance_threshold_vox == 1.5f; }}},
      {"esdf_min_weight", {"0.01", [](const SlamConfig& c) { return c.esdf.min_weight == 0.01f; }}},
      {"esdf_max_window_voxels",
       {"1000000", [](const SlamConfig& c) { return c.esdf.max_window_voxels == 1000000; }}},
      {"mesh_min_weight", {"0.02", [](const SlamConfig& c) { return c.mesh.min_weight == 0.02f; }}},
      {"submap_creation_policy",
       {"blocks",
        [](const SlamConfig& c) { return c.submaps.policy == SubmapCreationPolicy::kBlockCount; }}},
      {"submap_creation_interval_s",
       {"4.5", [](const SlamConfig& c) { return c.submaps.interval_s == 4.5; }}},
      {"submap_creation_distance_m",
       {"7", [](const SlamConfig& c) { return c.submaps.distance_m == 7.0; }}},
      {"submap_max_blocks",
       {"321", [](const SlamConfig& c) { return c.submaps.max_blocks == 321; }}},
      {"sensor_queue_size", {"3", [](const SlamConfig& c) { return c.sensor_queue_size == 3u; }}},
      {"submap_queue_size", {"9", [](const SlamConfig& c) { return c.submap_queue_size == 9u; }}},
      {"odometry_translation_sigma_m",
       {"0.7", [](const SlamConfig& c) { return c.odometry_translation_sigma_m == 0.7; }}},
      {"odometry_yaw_sigma_rad",
       {"0.05", [](const SlamConfig& c) { return c.odometry_yaw_sigma_rad == 0.05; }}},
      {"optimize_every_n_submaps",
       {"0", [](const SlamConfig& c) { return c.optimize_every_n_submaps == 0; }}},
      {"interpolate_trajectory_correction",
       {"true", [](const SlamConfig& c) { return c.interpolate_trajectory_correction; }}},
      {"external_stamp_tolerance_s",
       {"0.2", [](const SlamConfig& c) { return c.external_stamp_tolerance_s == 0.2; }}},
      {"solver_max_iterations",
       {"17", [](const SlamConfig& c) { return c.solver.max_iterations == 17; }}},
      {"solver_function_tolerance",
       {"1e-4", [](const SlamConfig& c) { return c.solver.function_tolerance == 1e-4; }}},
      {"solver_gradient_tolerance",
       {"1e-7", [](const SlamConfig& c) { return c.solver.gradient_tolerance == 1e-7; }}},
      {"solver_parameter_tolerance",
       {"1e-5", [](const SlamConfig& c) { return c.solver.parameter_tolerance == 1e-5; }}},
      {"solver_pcg_max_iterations",
       {"33", [](const SlamConfig& c) { return c.solver.pcg_max_iterations == 33; }}},
      {"solver_pcg_relative_tolerance",
       {"0.01", [](const SlamConfig& c) { return c.solver.pcg_relative_tolerance == 0.01; }}},
      {"solver_preconditioner",
       {"block_jacobi",
        [](const SlamConfig& c) {
          return c.solver.preconditioner == PcgPreconditioner::kBlockJacobi;
        }}},
      {"solver_chain_segment_vertices",
       {"0", [](const SlamConfig& c) { return c.solver.chain_segment_vertices == 0; }}},
      {"registration_enabled",
       {"false", [](const SlamConfig& c) { return !c.registration.enabled; }}},
      {"registration_mode",
       {"joint",
        [](const SlamConfig& c) { return c.registration.mode == RegistrationMode::kJoint; }}},
      {"registration_sampling_ratio",
       {"0.25", [](const SlamConfig& c) { return c.registration.sampling_ratio == 0.25f; }}},
      {"registration_distance",
       {"esdf",
        [](const SlamConfig& c) {
          return c.registration.distance == RegistrationDistance::kEsdf;
        }}},
      {"registration_symmetric",
       {"true", [](const SlamConfig& c) { return c.registration.symmetric; }}},
      {"registration_robust_loss",
       {"cauchy",
        [](const SlamConfig& c) { return c.registration.robust_loss == RobustLoss::kCauchy; }}},
      {"registration_robust_loss_scale_m",
       {"0.4", [](const SlamConfig& c) { return c.registration.robust_loss_scale_m == 0.4; }}},
      {"registration_point_sigma_m",
       {"0.05", [](const SlamConfig& c) { return c.registration.point_sigma_m == 0.05; }}},
      {"registration_min_sigma_m",
       {"0.5", [](const SlamConfig& c) { return c.registration.min_sigma_m == 0.5; }}},
      {"registration_min_sigma_yaw_rad",
       {"0.03", [](const SlamConfig& c) { return c.registration.min_sigma_yaw_rad == 0.03; }}},
      {"registration_min_shared_blocks",
       {"6", [](const SlamConfig& c) { return c.registration.min_shared_blocks == 6; }}},
      {"registration_min_points",
       {"250", [](const SlamConfig& c) { return c.registration.min_points == 250; }}},
      {"registration_max_correction_m",
       {"3.5", [](const SlamConfig& c) { return c.registration.max_correction_m == 3.5; }}},
      {"registration_max_correction_rad",
       {"0.5", [](const SlamConfig& c) { return c.registration.max_correction_rad == 0.5; }}},
      {"registration_inlier_distance_m",
       {"0.25", [](const SlamConfig& c) { return c.registration.inlier_distance_m == 0.25; }}},
      {"registration_min_inlier_fraction",
       {"0.6", [](const SlamConfig& c) { return c.registration.min_inlier_fraction == 0.6; }}},
      {"registration_min_fit_points",
       {"40", [](const SlamConfig& c) { return c.registration.min_fit_points == 40; }}},
      {"registration_search_enabled",
       {"true", [](const SlamConfig& c) { return c.registration.search_enabled; }}},
      {"registration_search_step_m",
       {"0.5", [](const SlamConfig& c) { return c.registration.search_step_m == 0.5; }}},
      {"registration_search_step_rad",
       {"0.02", [](const SlamConfig& c) { return c.registration.search_step_rad == 0.02; }}},
      {"registration_search_max_yaw_rad",
       {"0.3", [](const SlamConfig& c) { return c.registration.search_max_yaw_rad == 0.3; }}},
      {"registration_search_candidates",
       {"5", [](const SlamConfig& c) { return c.registration.search_candidates == 5; }}},
      {"registration_search_max_points",
       {"900", [](const SlamConfig& c) { return c.registration.search_max_points == 900; }}},
      {"registration_revisit_wall_search",
       {"true", [](const SlamConfig& c) { return c.registration.revisit_wall_search; }}},
      {"registration_revisit_min_id_gap",
       {"6", [](const SlamConfig& c) { return c.registration.revisit_min_id_gap == 6; }}},
      {"registration_wall_search_range_m",
       {"1.5", [](const SlamConfig& c) { return c.registration.wall_search_range_m == 1.5; }}},
      {"registration_wall_search_min_score",
       {"80", [](const SlamConfig& c) { return c.registration.wall_search_min_score == 80.0; }}},
      {"registration_wall_search_min_jump_m",
       {"0.3", [](const SlamConfig& c) { return c.registration.wall_search_min_jump_m == 0.3; }}},
      {"registration_max_partners",
       {"0", [](const SlamConfig& c) { return c.registration.max_partners == 0; }}},
      {"registration_max_iterations",
       {"25", [](const SlamConfig& c) { return c.registration.max_iterations == 25; }}},
      {"registration_coarse_levels",
       {"3", [](const SlamConfig& c) { return c.registration.coarse_levels == 3; }}},
      {"registration_max_graph_residual_m",
       {"0.75", [](const SlamConfig& c) { return c.registration.max_graph_residual_m == 0.75; }}},
      {"registration_gate_worst_fraction",
       {"0.25", [](const SlamConfig& c) { return c.registration.gate_worst_fraction == 0.25; }}},
  };
}

TEST(SlamParameterFiles, EveryNameSetsItsOwnField) {
  const std::map<std::string, Expectation> reference = expectations();
  const std::vector<std::string>& names = slam_parameter_names();
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size())
      << "a name is listed twice";
  for (const std::string& name : names) {
    EXPECT_TRUE(reference.count(name))
        << "'" << name << "' is readable but has no expectation in this test";
  }
  for (const auto& [name, expectation] : reference) {
    ASSERT_NE(std::find(names.begin(), names.end(), name), names.end())
        << "'" << name << "' is not readable";
    // Alone: it changes its own field (the defaults do not already hold the value)...
    SlamConfig config;
    // (The device's default is the CPU, the only device every machine has.)
    if (name != "device") {
      EXPECT_FALSE(expectation.holds(config))
          << name << ": pick a test value other than the default";
    }
    read_slam_config(
        TextParameterSource(std::map<std::string, std::string>{{name, expectation.value}}),
        &config);
    EXPECT_TRUE(expectation.holds(config))
        << name << " = " << expectation.value << " did not reach its field";
  }
  // ... and all together (a valid combination) each still lands in its own field.
  std::map<std::string, std::string> all;
  for (const auto& [name, expectation] : reference) all[name] = expectation.value;
  all["truncation_distance_m"] = "0.45";  // >= one voxel of 0.15 m
  SlamConfig config;
  read_slam_config(TextParameterSource(all), &config);
  for (const auto& [name, expectation] : reference) EXPECT_TRUE(expectation.holds(config)) << name;
}

using testing_support::expect_error_names;  // the error must name the wrong parameter

TEST(SlamParameterFiles, BadRegistrationAndSolverValuesAreReportedByName) {
  expect_error_names({{"registration_mode", "both"}}, "registration_mode");
  expect_error_names({{"registration_min_sigma_m", "-0.1"}}, "registration_min_sigma_m");
  expect_error_names({{"registration_min_inlier_fraction", "1.5"}},
                     "registration_min_inlier_fraction");
  expect_error_names({{"registration_inlier_distance_m", "0"}}, "registration_inlier_distance_m");
  expect_error_names({{"registration_coarse_levels", "7"}}, "registration_coarse_levels");
  expect_error_names({{"registration_coarse_levels", "-1"}}, "registration_coarse_levels");
  expect_error_names({{"registration_max_graph_residual_m", "-0.5"}},
                     "registration_max_graph_residual_m");
  expect_error_names({{"registration_gate_worst_fraction", "1"}},
                     "registration_gate_worst_fraction");
  expect_error_names({{"registration_min_fit_points", "-1"}}, "registration_min_fit_points");
  expect_error_names({{"registration_search_enabled", "maybe"}}, "registration_search_enabled");
  expect_error_names({{"registration_search_step_m", "-1"}}, "registration_search_step_m");
  expect_error_names({{"registration_search_candidates", "0"}}, "registration_search_candidates");
  expect_error_names({{"registration_search_max_points", "3"}}, "registration_search_max_points");
  expect_error_names({{"registration_revisit_min_id_gap", "0"}}, "registration_revisit_min_id_gap");
  expect_error_names({{"registration_wall_search_range_m", "-1"}},
                     "registration_wall_search_range_m");
  expect_error_names({{"registration_min_points", "2"}}, "registration_min_points");
  expect_error_names({{"registration_max_correction_rad", "4"}}, "registration_max_correction_rad");
  expect_error_names({{"solver_preconditioner", "jacobi"}}, "solver_preconditioner");
  expect_error_names({{"solver_pcg_relative_tolerance", "1.5"}}, "solver_pcg_relative_tolerance");
  expect_error_names({{"solver_chain_segment_vertices", "-2"}}, "solver_chain_segment_vertices");
  expect_error_names({{"esdf_max_window_voxels", "0"}}, "esdf_max_window_voxels");
}

// The SLAM keys of a parameter file: those slam_parameter_names() knows.
std::map<std::string, std::string> slam_keys(const std::map<std::string, std::string>& file) {
  const std::vector<std::string>& names = slam_parameter_names();
  std::map<std::string, std::string> keys;
  for (const auto& [name, value] : file) {
    if (std::find(names.begin(), names.end(), name) != names.end()) keys[name] = value;
  }
  return keys;
}

TEST(SlamParameterFiles, ShippedConfigsListAndDocumentEveryParameter) {
  const fs::path root = repository_root();
  const fs::path defaults_path = root / "config" / "covoxslam.yaml";
  ASSERT_TRUE(fs::exists(defaults_path)) << defaults_path;
  const std::map<std::string, std::string> defaults = tools::read_flat_yaml(defaults_path.string());
  // Every SLAM parameter has its line in covoxslam.yaml, with a comment (meaning and unit).
  std::ifstream defaults_text(defaults_path);
  std::map<std::string, std::string> lines;
  for (std::string line; std::getline(defaults_text, line);) {
    const size_t colon = line.find(':');
    if (colon != std::string::npos && !line.empty() && line[0] != '#' && line[0] != ' ')
      lines[line.substr(0, colon)] = line;
  }
  // The ROS documentation names every one too.
  std::ifstream ros_doc(root / "docs" / "ros.md");
  std::stringstream doc;
  doc << ros_doc.rdbuf();
  for (const std::string& name : slam_parameter_names()) {
    EXPECT_TRUE(defaults.count(name)) << "config/covoxslam.yaml lacks '" << name << "'";
    if (lines.count(name)) {
      EXPECT_NE(lines[name].find('#'), std::string::npos)
          << "config/covoxslam.yaml: '" << name << "' has no comment";
    }
    EXPECT_NE(doc.str().find("`" + name + "`"), std::string::npos)
        << "docs/ros.md does not name `" << name << "`";
  }
  // Both files are valid as shipped: the defaults alone, and arche.yaml on top of them.
  SlamConfig config;
  ASSERT_NO_THROW(read_slam_config(TextParameterSource(slam_keys(defaults)), &config));
  std::map<std::string, std::string> arche = slam_keys(defaults);
  for (const auto& [name, value] :
       slam_keys(tools::read_flat_yaml((root / "config" / "arche.yaml").string()))) {
    arche[name] = value;
  }
  SlamConfig arche_config;
  ASSERT_NO_THROW(read_slam_config(TextParameterSource(arche), &arche_config));
  EXPECT_FLOAT_EQ(arche_config.tsdf.sparsity_compensation_factor,
                  20.0f);  // voxgraph's ARCHE setting
}

// config/arche_sim.yaml is the offline runner's ARCHE preset for the ROS node (what `make demo`
// measures): every SLAM setting the preset changes reads back the same from the file.
TEST(SlamParameterFiles, ArcheSimFileEqualsTheRunnersArchePreset) {
  const fs::path root = repository_root();
  std::map<std::string, std::string> keys =
      slam_keys(tools::read_flat_yaml((root / "config" / "covoxslam.yaml").string()));
  for (const auto& [name, value] :
       slam_keys(tools::read_flat_yaml((root / "config" / "arche_sim.yaml").string()))) {
    keys[name] = value;
  }
  SlamConfig file;
  ASSERT_NO_THROW(read_slam_config(TextParameterSource(keys), &file));
  const SlamConfig preset = tools::arche_slam_config(Device::kCpu);
  EXPECT_EQ(file.map.voxel_size_m, preset.map.voxel_size_m);
  EXPECT_EQ(file.map.voxels_per_side, preset.map.voxels_per_side);
  EXPECT_EQ(file.tsdf.truncation_distance_m, preset.tsdf.truncation_distance_m);
  EXPECT_EQ(file.tsdf.max_ray_length_m, preset.tsdf.max_ray_length_m);
  EXPECT_EQ(file.tsdf.use_const_weight, preset.tsdf.use_const_weight);
  EXPECT_EQ(file.tsdf.use_weight_dropoff, preset.tsdf.use_weight_dropoff);
  EXPECT_EQ(file.tsdf.use_sparsity_compensation_factor,
            preset.tsdf.use_sparsity_compensation_factor);
  EXPECT_EQ(file.tsdf.sparsity_compensation_factor, preset.tsdf.sparsity_compensation_factor);
  EXPECT_EQ(file.submaps.policy, preset.submaps.policy);
  EXPECT_EQ(file.submaps.interval_s, preset.submaps.interval_s);
  EXPECT_EQ(file.registration.symmetric, preset.registration.symmetric);
  EXPECT_EQ(file.registration.sampling_ratio, preset.registration.sampling_ratio);
  EXPECT_EQ(file.registration.robust_loss, preset.registration.robust_loss);
  EXPECT_EQ(file.registration.min_sigma_m, preset.registration.min_sigma_m);
  EXPECT_NEAR(file.registration.min_sigma_yaw_rad, preset.registration.min_sigma_yaw_rad, 1e-6);
  EXPECT_EQ(file.registration.max_correction_m, preset.registration.max_correction_m);
  EXPECT_EQ(file.registration.coarse_levels, preset.registration.coarse_levels);
  EXPECT_EQ(file.registration.search_enabled, preset.registration.search_enabled);
  EXPECT_EQ(file.registration.revisit_wall_search, preset.registration.revisit_wall_search);
  EXPECT_EQ(file.registration.max_graph_residual_m, preset.registration.max_graph_residual_m);
  EXPECT_EQ(file.registration.gate_worst_fraction, preset.registration.gate_worst_fraction);
  EXPECT_EQ(file.interpolate_trajectory_correction, preset.interpolate_trajectory_correction);
  EXPECT_EQ(file.odometry_translation_sigma_m, preset.odometry_translation_sigma_m);
  EXPECT_EQ(file.odometry_yaw_sigma_rad, preset.odometry_yaw_sigma_rad);
}

}  // namespace
}  // namespace pipeline
}  // namespace covox
