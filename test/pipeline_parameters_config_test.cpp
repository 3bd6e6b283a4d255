// Every SLAM parameter name reaches its SlamConfig field; docs/parameters.md documents every one;
// the shipped configuration files (the presets) hold only known keys, set only what differs from
// the library defaults, and give the values they were measured with.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include <unistd.h>

#include "covoxslam/core/error.h"
#include "covoxslam/io/yaml_subset.h"
#include "covoxslam/pipeline/slam_config_files.h"
#include "covoxslam/pipeline/slam_parameters.h"
#include "support/parameter_errors.h"

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
      {"map.voxel_size_m",
       {"0.15", [](const SlamConfig& c) { return c.map.voxel_size_m == 0.15f; }}},
      {"map.voxels_per_side",
       {"8", [](const SlamConfig& c) { return c.map.voxels_per_side == 8; }}},
      {"map.block_table.initial_bucket_count",
       {"1234",
        [](const SlamConfig& c) { return c.map.block_table.initial_bucket_count == 1234u; }}},
      {"map.block_table.max_load_factor",
       {"0.5", [](const SlamConfig& c) { return c.map.block_table.max_load_factor == 0.5; }}},
      {"map.block_table.allow_growth",
       {"false", [](const SlamConfig& c) { return !c.map.block_table.allow_growth; }}},
      {"tsdf.method",
       {"simple",
        [](const SlamConfig& c) {
          return c.tsdf.method == integrators::TsdfIntegrationMethod::kSimple;
        }}},
      {"tsdf.truncation_distance_m",
       {"0.45", [](const SlamConfig& c) { return c.tsdf.truncation_distance_m == 0.45f; }}},
      {"tsdf.max_weight", {"77", [](const SlamConfig& c) { return c.tsdf.max_weight == 77.0f; }}},
      {"tsdf.min_ray_length_m",
       {"0.3", [](const SlamConfig& c) { return c.tsdf.min_ray_length_m == 0.3f; }}},
      {"tsdf.max_ray_length_m",
       {"12.5", [](const SlamConfig& c) { return c.tsdf.max_ray_length_m == 12.5f; }}},
      {"tsdf.voxel_carving_enabled",
       {"false", [](const SlamConfig& c) { return !c.tsdf.voxel_carving_enabled; }}},
      {"tsdf.allow_clear", {"false", [](const SlamConfig& c) { return !c.tsdf.allow_clear; }}},
      {"tsdf.use_const_weight",
       {"true", [](const SlamConfig& c) { return c.tsdf.use_const_weight; }}},
      {"tsdf.use_weight_dropoff",
       {"false", [](const SlamConfig& c) { return !c.tsdf.use_weight_dropoff; }}},
      {"tsdf.use_sparsity_compensation_factor",
       {"true", [](const SlamConfig& c) { return c.tsdf.use_sparsity_compensation_factor; }}},
      {"tsdf.sparsity_compensation_factor",
       {"20", [](const SlamConfig& c) { return c.tsdf.sparsity_compensation_factor == 20.0f; }}},
      {"tsdf.integrate_color",
       {"false", [](const SlamConfig& c) { return !c.tsdf.integrate_color; }}},
      {"tsdf.fixed_point_sums_max_scratch_mb",
       {"64", [](const SlamConfig& c) { return c.tsdf.fixed_point_sums_max_scratch_mb == 64; }}},
      {"esdf.max_distance_m",
       {"3", [](const SlamConfig& c) { return c.esdf.esdf_max_distance_m == 3.0f; }}},
      {"esdf.site_distance_threshold_vox",
       {"1.5", [](const SlamConfig& c) { return c.esdf.site_distance_threshold_vox == 1.5f; }}},
      {"esdf.min_weight", {"0.01", [](const SlamConfig& c) { return c.esdf.min_weight == 0.01f; }}},
      {"esdf.max_window_voxels",
       {"1000000", [](const SlamConfig& c) { return c.esdf.max_window_voxels == 1000000; }}},
      {"mesh.min_weight", {"0.02", [](const SlamConfig& c) { return c.mesh.min_weight == 0.02f; }}},
      {"submaps.policy",
       {"blocks",
        [](const SlamConfig& c) { return c.submaps.policy == SubmapCreationPolicy::kBlockCount; }}},
      {"deskew.enabled", {"false", [](const SlamConfig& c) { return !c.deskew.enabled; }}},
      {"deskew.sweep_duration_s",
       {"0.05", [](const SlamConfig& c) { return c.deskew.sweep_duration_s == 0.05; }}},
      {"submaps.interval_s",
       {"4.5", [](const SlamConfig& c) { return c.submaps.interval_s == 4.5; }}},
      {"submaps.distance_m",
       {"7", [](const SlamConfig& c) { return c.submaps.distance_m == 7.0; }}},
      {"submaps.max_blocks",
       {"321", [](const SlamConfig& c) { return c.submaps.max_blocks == 321; }}},
      {"queues.sensor_scans", {"3", [](const SlamConfig& c) { return c.sensor_queue_size == 3u; }}},
      {"queues.submaps", {"9", [](const SlamConfig& c) { return c.submap_queue_size == 9u; }}},
      {"queues.wait_when_full",
       {"true", [](const SlamConfig& c) { return c.wait_when_queues_full; }}},
      {"memory.device_budget_mb",
       {"640", [](const SlamConfig& c) { return c.memory.device_budget_mb == 640.0; }}},
      {"memory.host_budget_mb",
       {"320", [](const SlamConfig& c) { return c.memory.host_budget_mb == 320.0; }}},
      {"memory.device_cache_mb",
       {"64", [](const SlamConfig& c) { return c.memory.device_cache_mb == 64.0; }}},
      {"memory.spill_directory",
       {"/var/spill",
        [](const SlamConfig& c) { return c.memory.spill_directory == "/var/spill"; }}},
      {"pose_graph.odometry_translation_sigma_vox",
       {"0.7", [](const SlamConfig& c) { return c.odometry_translation_sigma_vox == 0.7; }}},
      {"pose_graph.odometry_yaw_sigma_rad",
       {"0.05", [](const SlamConfig& c) { return c.odometry_yaw_sigma_rad == 0.05; }}},
      {"pose_graph.odometry_drift_m_per_m",
       {"0.07", [](const SlamConfig& c) { return c.odometry_drift_m_per_m == 0.07; }}},
      {"pose_graph.odometry_drift_deg_per_m",
       {"1.5", [](const SlamConfig& c) { return c.odometry_drift_deg_per_m == 1.5; }}},
      {"pose_graph.estimate_odometry_noise",
       {"false", [](const SlamConfig& c) { return !c.estimate_odometry_noise; }}},
      {"pose_graph.min_odometry_drift_m_per_m",
       {"0.02", [](const SlamConfig& c) { return c.min_odometry_drift_m_per_m == 0.02; }}},
      {"pose_graph.min_odometry_drift_deg_per_m",
       {"0.3", [](const SlamConfig& c) { return c.min_odometry_drift_deg_per_m == 0.3; }}},
      {"pose_graph.revisit_drift_min_path_m",
       {"250", [](const SlamConfig& c) { return c.revisit_drift_min_path_m == 250.0; }}},
      {"pose_graph.registration_loss_scale_sigmas",
       {"2.5", [](const SlamConfig& c) { return c.registration_loss_scale_sigmas == 2.5; }}},
      {"registration.acceptance.max_residual_rms_vox",
       {"1.5",
        [](const SlamConfig& c) { return c.registration.acceptance.max_residual_rms_vox == 1.5; }}},
      {"registration.verification.max_mahalanobis_sq",
       {"13.0",
        [](const SlamConfig& c) {
          return c.registration.verification.max_mahalanobis_sq == 13.0;
        }}},
      {"pose_graph.optimize_every_n_submaps",
       {"0", [](const SlamConfig& c) { return c.optimize_every_n_submaps == 0; }}},
      {"pose_graph.optimize_spacing_fraction",
       {"0.25", [](const SlamConfig& c) { return c.optimize_spacing_fraction == 0.25; }}},
      {"pose_graph.max_solves_per_new_submap",
       {"7", [](const SlamConfig& c) { return c.max_solves_per_new_submap == 7; }}},
      {"pose_graph.interpolate_trajectory_correction",
       {"false", [](const SlamConfig& c) { return !c.interpolate_trajectory_correction; }}},
      {"pose_graph.external_stamp_tolerance_s",
       {"0.2", [](const SlamConfig& c) { return c.external_stamp_tolerance_s == 0.2; }}},
      {"solver.max_iterations",
       {"17", [](const SlamConfig& c) { return c.solver.max_iterations == 17; }}},
      {"solver.function_tolerance",
       {"1e-4", [](const SlamConfig& c) { return c.solver.function_tolerance == 1e-4; }}},
      {"solver.gradient_tolerance",
       {"1e-7", [](const SlamConfig& c) { return c.solver.gradient_tolerance == 1e-7; }}},
      {"solver.parameter_tolerance",
       {"1e-5", [](const SlamConfig& c) { return c.solver.parameter_tolerance == 1e-5; }}},
      {"solver.pcg_max_iterations",
       {"33", [](const SlamConfig& c) { return c.solver.pcg_max_iterations == 33; }}},
      {"solver.pcg_relative_tolerance",
       {"0.01", [](const SlamConfig& c) { return c.solver.pcg_relative_tolerance == 0.01; }}},
      {"solver.preconditioner",
       {"block_jacobi",
        [](const SlamConfig& c) {
          return c.solver.preconditioner == PcgPreconditioner::kBlockJacobi;
        }}},
      {"solver.chain_segment_vertices",
       {"0", [](const SlamConfig& c) { return c.solver.chain_segment_vertices == 0; }}},
      {"registration.enabled",
       {"false", [](const SlamConfig& c) { return !c.registration.enabled; }}},
      {"registration.mode",
       {"joint",
        [](const SlamConfig& c) { return c.registration.mode == RegistrationMode::kJoint; }}},
      {"registration.overlap.min_shared_blocks",
       {"6", [](const SlamConfig& c) { return c.registration.overlap.min_shared_blocks == 6; }}},
      {"registration.overlap.max_partners",
       {"0", [](const SlamConfig& c) { return c.registration.overlap.max_partners == 0; }}},
      {"registration.overlap.max_visits",
       {"5", [](const SlamConfig& c) { return c.registration.overlap.max_visits == 5; }}},
      {"registration.sampling.ratio",
       {"0.25", [](const SlamConfig& c) { return c.registration.sampling.ratio == 0.25f; }}},
      {"registration.alignment.distance",
       {"esdf",
        [](const SlamConfig& c) {
          return c.registration.alignment.distance == RegistrationDistance::kEsdf;
        }}},
      {"registration.alignment.symmetric",
       {"false", [](const SlamConfig& c) { return !c.registration.alignment.symmetric; }}},
      {"registration.alignment.robust_loss",
       {"cauchy",
        [](const SlamConfig& c) {
          return c.registration.alignment.robust_loss == RobustLoss::kCauchy;
        }}},
      {"registration.alignment.robust_loss_scale_m",
       {"0.4",
        [](const SlamConfig& c) { return c.registration.alignment.robust_loss_scale_m == 0.4; }}},
      {"registration.alignment.max_iterations",
       {"25", [](const SlamConfig& c) { return c.registration.alignment.max_iterations == 25; }}},
      {"registration.alignment.coarse_levels",
       {"3", [](const SlamConfig& c) { return c.registration.alignment.coarse_levels == 3; }}},
      {"registration.acceptance.min_points",
       {"250", [](const SlamConfig& c) { return c.registration.acceptance.min_points == 250; }}},
      {"registration.acceptance.max_correction_m",
       {"2.5",
        [](const SlamConfig& c) { return c.registration.acceptance.max_correction_m == 2.5; }}},
      {"registration.acceptance.max_correction_rad",
       {"0.5",
        [](const SlamConfig& c) { return c.registration.acceptance.max_correction_rad == 0.5; }}},
      {"registration.information.point_sigma_m",
       {"0.05",
        [](const SlamConfig& c) { return c.registration.information.point_sigma_m == 0.05; }}},
      {"registration.information.min_sigma_vox",
       {"0.5",
        [](const SlamConfig& c) { return c.registration.information.min_sigma_vox == 0.5; }}},
      {"registration.information.min_sigma_yaw_rad",
       {"0.03",
        [](const SlamConfig& c) { return c.registration.information.min_sigma_yaw_rad == 0.03; }}},
      {"registration.revisits.wall_search",
       {"false", [](const SlamConfig& c) { return !c.registration.revisits.wall_search; }}},
      {"registration.revisits.min_id_gap",
       {"6", [](const SlamConfig& c) { return c.registration.revisits.min_id_gap == 6; }}},
      {"registration.revisits.wall_search_range_m",
       {"1.5",
        [](const SlamConfig& c) { return c.registration.revisits.wall_search_range_m == 1.5; }}},
      {"registration.revisits.wall_search_min_score",
       {"80",
        [](const SlamConfig& c) { return c.registration.revisits.wall_search_min_score == 80.0; }}},
      {"registration.revisits.wall_search_min_jump_m",
       {"0.3",
        [](const SlamConfig& c) { return c.registration.revisits.wall_search_min_jump_m == 0.3; }}},
      {"registration.gate.max_residual_vox",
       {"0.75", [](const SlamConfig& c) { return c.registration.gate.max_residual_vox == 0.75; }}},
      {"registration.gate.worst_fraction",
       {"0.25", [](const SlamConfig& c) { return c.registration.gate.worst_fraction == 0.25; }}},
      {"place_recognition.enabled",
       {"false", [](const SlamConfig& c) { return !c.place_recognition.enabled; }}},
      {"place_recognition.rings",
       {"12", [](const SlamConfig& c) { return c.place_recognition.rings == 12; }}},
      {"place_recognition.sectors",
       {"36", [](const SlamConfig& c) { return c.place_recognition.sectors == 36; }}},
      {"place_recognition.max_radius_m",
       {"15", [](const SlamConfig& c) { return c.place_recognition.max_radius_m == 15.0; }}},
      {"place_recognition.candidates",
       {"3", [](const SlamConfig& c) { return c.place_recognition.candidates == 3; }}},
      {"place_recognition.anchor_spacing_m",
       {"4", [](const SlamConfig& c) { return c.place_recognition.anchor_spacing_m == 4.0; }}},
      {"place_recognition.exclude_recent_submaps",
       {"9", [](const SlamConfig& c) { return c.place_recognition.exclude_recent_submaps == 9; }}},
      {"place_recognition.max_descriptor_distance",
       {"0.3",
        [](const SlamConfig& c) { return c.place_recognition.max_descriptor_distance == 0.3; }}},
      {"place_recognition.translation_search_m",
       {"6", [](const SlamConfig& c) { return c.place_recognition.translation_search_m == 6.0; }}},
      {"place_recognition.min_overlap_score",
       {"0.45", [](const SlamConfig& c) { return c.place_recognition.min_overlap_score == 0.45; }}},
      {"place_recognition.max_residual_rms_vox",
       {"0.6",
        [](const SlamConfig& c) { return c.place_recognition.max_residual_rms_vox == 0.6; }}},
      {"place_recognition.odometry_drift_m_per_m",
       {"0.05",
        [](const SlamConfig& c) { return c.place_recognition.odometry_drift_m_per_m == 0.05; }}},
      {"place_recognition.odometry_drift_deg_per_m",
       {"0.3",
        [](const SlamConfig& c) { return c.place_recognition.odometry_drift_deg_per_m == 0.3; }}},
      {"place_recognition.confirm_window_submaps",
       {"7", [](const SlamConfig& c) { return c.place_recognition.confirm_window_submaps == 7; }}},
      {"place_recognition.confirm_tolerance_m",
       {"1.5", [](const SlamConfig& c) { return c.place_recognition.confirm_tolerance_m == 1.5; }}},
      {"place_recognition.confirm_tolerance_deg",
       {"4", [](const SlamConfig& c) { return c.place_recognition.confirm_tolerance_deg == 4.0; }}},
      {"place_recognition.max_odometry_mahalanobis_sq",
       {"9",
        [](const SlamConfig& c) {
          return c.place_recognition.max_odometry_mahalanobis_sq == 9.0;
        }}},
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
  all["tsdf.truncation_distance_m"] = "0.45";  // >= one voxel of 0.15 m
  SlamConfig config;
  read_slam_config(TextParameterSource(all), &config);
  for (const auto& [name, expectation] : reference) EXPECT_TRUE(expectation.holds(config)) << name;
}

using testing_support::expect_error_names;  // the error must name the wrong parameter

TEST(SlamParameterFiles, BadRegistrationAndSolverValuesAreReportedByName) {
  expect_error_names({{"registration.mode", "both"}}, "registration.mode");
  expect_error_names({{"registration.information.min_sigma_vox", "-0.1"}},
                     "registration.information.min_sigma_vox");
  expect_error_names({{"registration.alignment.coarse_levels", "7"}},
                     "registration.alignment.coarse_levels");
  expect_error_names({{"registration.alignment.coarse_levels", "-1"}},
                     "registration.alignment.coarse_levels");
  expect_error_names({{"registration.gate.max_residual_vox", "-0.5"}},
                     "registration.gate.max_residual_vox");
  expect_error_names({{"registration.gate.worst_fraction", "1"}},
                     "registration.gate.worst_fraction");
  expect_error_names({{"registration.revisits.wall_search", "maybe"}},
                     "registration.revisits.wall_search");
  expect_error_names({{"registration.revisits.min_id_gap", "0"}},
                     "registration.revisits.min_id_gap");
  expect_error_names({{"registration.revisits.wall_search_range_m", "-1"}},
                     "registration.revisits.wall_search_range_m");
  expect_error_names({{"registration.acceptance.min_points", "2"}},
                     "registration.acceptance.min_points");
  expect_error_names({{"registration.acceptance.max_correction_rad", "4"}},
                     "registration.acceptance.max_correction_rad");
  expect_error_names({{"solver.preconditioner", "jacobi"}}, "solver.preconditioner");
  expect_error_names({{"solver.pcg_relative_tolerance", "1.5"}}, "solver.pcg_relative_tolerance");
  expect_error_names({{"solver.chain_segment_vertices", "-2"}}, "solver.chain_segment_vertices");
  expect_error_names({{"esdf.max_window_voxels", "0"}}, "esdf.max_window_voxels");
}

// The text of docs/parameters.md, the one place every parameter is documented.
std::string parameters_doc() {
  std::ifstream file(repository_root() / "docs" / "parameters.md");
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

std::vector<fs::path> config_files() {
  std::vector<fs::path> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(repository_root() / "config")) {
    if (entry.path().extension() == ".yaml") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

TEST(SlamParameterFiles, EveryParameterIsDocumentedOnce) {
  const std::string doc = parameters_doc();
  ASSERT_FALSE(doc.empty()) << "docs/parameters.md is missing";
  for (const std::string& name : slam_parameter_names()) {
    const std::string cell = "| `" + name + "` |";
    const size_t first = doc.find(cell);
    EXPECT_NE(first, std::string::npos) << "docs/parameters.md has no row for `" << name << "`";
    if (first != std::string::npos) {
      EXPECT_EQ(doc.find(cell, first + 1), std::string::npos) << name << " is documented twice";
    }
  }
}

// Every key of every shipped configuration file is known: the SLAM ones load (an unknown one is an
// error), the nodelet's (`ros` section) are documented parameters of the nodelet.
TEST(SlamParameterFiles, EveryKeyOfEveryShippedFileIsKnown) {
  const std::string doc = parameters_doc();
  const std::vector<fs::path> files = config_files();
  ASSERT_GE(files.size(), 5u);
  for (const fs::path& file : files) {
    SlamConfig config;
    SlamConfigFileUse use;
    ASSERT_NO_THROW(use = load_slam_config(file.string(), &config)) << file;
    EXPECT_GT(use.applied, 0u) << file;
    for (const std::string& key : use.node_keys) {
      EXPECT_NE(doc.find("| `" + key + "` |"), std::string::npos)
          << file << ": '" << key << "' is not a documented parameter of the nodelet";
    }
  }
  EXPECT_EQ(preset_names(),
            (std::vector<std::string>{"arche", "covoxslam", "jetson", "lidar_keyframes", "rgbd"}));
}

// A preset sets only what differs from the library defaults: each of its SLAM keys alone changes
// the fields below (those the shipped presets set).
std::string describe(const SlamConfig& config) {
  std::ostringstream text;
  text.precision(17);
  const SlamConfig& c = config;
  text << c.map.voxel_size_m << ' ' << c.tsdf.truncation_distance_m << ' '
       << c.tsdf.max_ray_length_m << ' ' << c.tsdf.use_const_weight << ' '
       << c.tsdf.use_weight_dropoff << ' ' << c.tsdf.use_sparsity_compensation_factor << ' '
       << c.tsdf.sparsity_compensation_factor << ' ' << c.submaps.interval_s << ' '
       << c.odometry_translation_sigma_vox << ' ' << c.odometry_yaw_sigma_rad << ' '
       << c.interpolate_trajectory_correction << ' ' << c.registration.alignment.coarse_levels
       << ' ' << c.registration.information.min_sigma_vox << ' '
       << c.registration.information.min_sigma_yaw_rad << ' ' << c.registration.revisits.wall_search
       << ' ' << c.registration.gate.max_residual_vox << ' '
       << c.registration.acceptance.max_residual_rms_vox << ' '
       << c.registration.verification.max_mahalanobis_sq << ' ' << c.odometry_drift_m_per_m << ' '
       << c.odometry_drift_deg_per_m << ' ' << c.registration_loss_scale_sigmas << ' '
       << c.estimate_odometry_noise << ' ' << c.min_odometry_drift_m_per_m << ' '
       << c.min_odometry_drift_deg_per_m << ' ' << c.memory.device_budget_mb << ' '
       << c.memory.host_budget_mb << ' ' << c.memory.device_cache_mb;
  return text.str();
}

TEST(SlamParameterFiles, PresetsListOnlyWhatDiffersFromTheDefaults) {
  for (const char* preset : {"arche", "rgbd", "lidar_keyframes", "covoxslam", "jetson"}) {
    const io::YamlDocument document = io::read_yaml_subset(preset_path(preset));
    for (const io::YamlEntry& entry : document.entries) {
      if (entry.key.compare(0, 4, "ros.") == 0) continue;
      SlamConfig config;
      try {
        read_slam_config(
            TextParameterSource(std::map<std::string, std::string>{{entry.key, entry.value}}),
            &config);
      } catch (const Error& error) {
        // Alone, a value may break a relation with the defaults (a truncation below the default
        // voxel): the relations are checked after every field was read, so the field is set.
        EXPECT_EQ(std::string(error.what()).rfind("parameters: ", 0), 0u) << error.what();
      }
      EXPECT_NE(describe(config), describe(SlamConfig()))
          << document.where(entry) << " " << entry.key << " is the default";
    }
  }
}

// One configuration for every input: a preset holds the facts of its sensor (resolution, range,
// weighting, submap length, memory budgets) and none of the settings that say how far the
// odometry and the registrations are trusted, which are the library's defaults. The one known
// exception (docs/decisions.md, "one configuration") is listed by name.
TEST(SlamParameterFiles, PresetsHoldSensorFactsOnly) {
  const std::set<std::string> exceptions = {
      "lidar_keyframes registration.information.min_sigma_vox"};
  const std::vector<std::string> sensor_facts = {"map.voxel_size_m",
                                                 "tsdf.truncation_distance_m",
                                                 "tsdf.max_ray_length_m",
                                                 "tsdf.use_const_weight",
                                                 "tsdf.use_weight_dropoff",
                                                 "tsdf.use_sparsity_compensation_factor",
                                                 "tsdf.sparsity_compensation_factor",
                                                 "submaps.interval_s",
                                                 "memory.device_budget_mb",
                                                 "memory.host_budget_mb",
                                                 "memory.device_cache_mb"};
  for (const std::string& preset : preset_names()) {
    for (const io::YamlEntry& entry : io::read_yaml_subset(preset_path(preset)).entries) {
      if (entry.key.compare(0, 4, "ros.") == 0) continue;
      if (exceptions.count(preset + " " + entry.key)) continue;
      EXPECT_NE(std::find(sensor_facts.begin(), sensor_facts.end(), entry.key), sensor_facts.end())
          << preset << ": " << entry.key << " is not a sensor fact";
    }
  }
}

// The one configuration as it was measured and documented (written out here, not read from the
// code), and the presets' sensor facts.
TEST(SlamParameterFiles, DefaultsAndPresetsGiveTheirDocumentedValues) {
  const SlamConfig defaults;
  EXPECT_EQ(defaults.submaps.interval_s, 5.0);
  EXPECT_EQ(defaults.registration.alignment.coarse_levels, 2);
  EXPECT_TRUE(defaults.registration.alignment.symmetric);
  EXPECT_EQ(defaults.registration.acceptance.max_correction_m, 3.5);
  EXPECT_EQ(defaults.registration.acceptance.max_residual_rms_vox, 1.0);
  EXPECT_EQ(defaults.registration.information.min_sigma_vox, 1.0);
  EXPECT_EQ(defaults.registration.information.min_sigma_yaw_rad,
            1.0 * 3.14159265358979323846 / 180.0);
  EXPECT_TRUE(defaults.registration.revisits.wall_search);
  EXPECT_EQ(defaults.registration.gate.max_residual_vox, 3.0);
  EXPECT_EQ(defaults.registration.gate.worst_fraction, 0.7);
  EXPECT_EQ(defaults.registration.verification.max_mahalanobis_sq, 18.5);
  EXPECT_TRUE(defaults.interpolate_trajectory_correction);
  EXPECT_EQ(defaults.odometry_translation_sigma_vox, 0.25);
  EXPECT_EQ(defaults.odometry_yaw_sigma_rad, 0.002);
  EXPECT_EQ(defaults.odometry_drift_m_per_m, 0.1);
  EXPECT_EQ(defaults.odometry_drift_deg_per_m, 2.0);
  EXPECT_TRUE(defaults.estimate_odometry_noise);
  EXPECT_EQ(defaults.min_odometry_drift_m_per_m, 0.005);
  EXPECT_EQ(defaults.min_odometry_drift_deg_per_m, 0.02);
  EXPECT_EQ(defaults.registration_loss_scale_sigmas, 3.0);

  const SlamConfig arche = load_preset("arche");  // the OS1-64 of the ARCHE and simulated flights
  EXPECT_EQ(arche.map.voxel_size_m, 0.2f);
  EXPECT_EQ(arche.tsdf.truncation_distance_m, 0.6f);
  EXPECT_EQ(arche.tsdf.max_ray_length_m, 24.0f);
  EXPECT_TRUE(arche.tsdf.use_const_weight);
  EXPECT_TRUE(arche.tsdf.use_weight_dropoff);
  EXPECT_TRUE(arche.tsdf.use_sparsity_compensation_factor);
  EXPECT_EQ(arche.tsdf.sparsity_compensation_factor, 20.0f);
  EXPECT_EQ(arche.submaps.interval_s, 5.0);

  const SlamConfig rgbd = load_preset("rgbd");
  EXPECT_EQ(rgbd.map.voxel_size_m, 0.04f);
  EXPECT_EQ(rgbd.tsdf.truncation_distance_m, 0.12f);
  EXPECT_EQ(rgbd.tsdf.max_ray_length_m, 4.0f);
  EXPECT_FALSE(rgbd.tsdf.use_const_weight);
  EXPECT_FALSE(rgbd.tsdf.use_sparsity_compensation_factor);
  EXPECT_EQ(rgbd.submaps.interval_s, 2.0);

  const SlamConfig keyframes = load_preset("lidar_keyframes");
  EXPECT_EQ(keyframes.map.voxel_size_m, 0.5f);
  EXPECT_EQ(keyframes.tsdf.truncation_distance_m, 1.5f);
  EXPECT_EQ(keyframes.tsdf.max_ray_length_m, 40.0f);
  EXPECT_TRUE(keyframes.tsdf.use_const_weight);
  EXPECT_EQ(keyframes.tsdf.sparsity_compensation_factor, 20.0f);
  EXPECT_EQ(keyframes.submaps.interval_s, 8.0);
  EXPECT_EQ(keyframes.registration.information.min_sigma_vox, 0.35);
}

// The Jetson preset holds memory budgets only: loaded over another preset, it leaves that one's
// sensor and mapping settings as they are.
TEST(SlamParameterFiles, JetsonPresetSetsOnlyMemoryBudgets) {
  for (const io::YamlEntry& entry : io::read_yaml_subset(preset_path("jetson")).entries)
    EXPECT_EQ(entry.key.rfind("memory.", 0), 0u) << entry.key;
  const SlamConfig sim = load_preset("arche");
  SlamConfig config = sim;
  load_slam_config(preset_path("jetson"), &config);
  EXPECT_EQ(config.memory.device_budget_mb, 768.0);
  EXPECT_EQ(config.memory.host_budget_mb, 256.0);
  EXPECT_EQ(config.memory.device_cache_mb, 128.0);
  EXPECT_EQ(config.memory.spill_directory, "");
  config.memory = sim.memory;
  EXPECT_EQ(describe(config), describe(sim));
  EXPECT_NO_THROW(validate(config));
}

// A temporary configuration folder, found through COVOX_CONFIG_DIR while it lives.
class ConfigFolder {
 public:
  ConfigFolder()
      : path_(fs::path(::testing::TempDir()) /
              ("covoxslam_config_test_" + std::to_string(::getpid()))) {
    fs::create_directories(path_);
    ::setenv("COVOX_CONFIG_DIR", path_.c_str(), 1);
  }
  ~ConfigFolder() {
    ::unsetenv("COVOX_CONFIG_DIR");
    fs::remove_all(path_);
  }
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path file = path_ / name;
    std::ofstream(file) << text;
    return file.string();
  }

 private:
  fs::path path_;
};

TEST(SlamParameterFiles, TheConfigFolderCanBeMovedAndUnknownPresetsListTheKnownOnes) {
  const ConfigFolder folder;
  folder.write("small.yaml", "map:\n  voxel_size_m: 0.1\ntsdf:\n  truncation_distance_m: 0.3\n");
  EXPECT_EQ(preset_names(), std::vector<std::string>{"small"});
  EXPECT_EQ(load_preset("small").map.voxel_size_m, 0.1f);
  try {
    load_preset("arche");
    ADD_FAILURE() << "no error for an unknown preset";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("'arche'"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("small"), std::string::npos) << error.what();
  }
}

TEST(SlamParameterFiles, FileErrorsNameTheFileAndLine) {
  const ConfigFolder folder;
  auto error_of = [](const std::string& path) {
    SlamConfig config;
    try {
      load_slam_config(path, &config);
    } catch (const Error& error) {
      EXPECT_EQ(config.map.voxel_size_m, SlamConfig().map.voxel_size_m) << "changed on error";
      return std::string(error.what());
    }
    return std::string("no error");
  };
  const std::string unknown =
      folder.write("unknown.yaml", "map:\n  voxel_size_m: 0.1\n  voxel_size: 0.1\n");
  EXPECT_NE(error_of(unknown).find(unknown + ":3: unknown parameter 'map.voxel_size'"),
            std::string::npos)
      << error_of(unknown);
  const std::string bad = folder.write("bad.yaml", "# a comment\nmap:\n  voxel_size_m: -1\n");
  EXPECT_NE(error_of(bad).find(bad + ":3: parameter 'map.voxel_size_m': must be positive"),
            std::string::npos)
      << error_of(bad);
  const std::string flat = folder.write("flat.yaml", "voxel_size_m: 0.1\n");
  EXPECT_NE(error_of(flat).find(flat + ":1: unknown parameter 'voxel_size_m'"), std::string::npos)
      << error_of(flat);
  // A trust setting that became a voxel count: the error names the new key and the conversion.
  const std::string old_gate =
      folder.write("old_gate.yaml", "registration:\n  gate:\n    max_residual_m: 0.3\n");
  EXPECT_NE(error_of(old_gate).find(old_gate +
                                    ":3: parameter 'registration.gate.max_residual_m': renamed "
                                    "to 'registration.gate.max_residual_vox', in voxels"),
            std::string::npos)
      << error_of(old_gate);
  const std::vector<std::string>& names = slam_parameter_names();
  EXPECT_NE(std::find(names.begin(), names.end(), "registration.gate.max_residual_vox"),
            names.end());
}

}  // namespace
}  // namespace pipeline
}  // namespace covox
