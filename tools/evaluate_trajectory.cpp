// evaluate_trajectory: ATE / RPE of one or more estimated trajectories against a reference (TUM
// files, or a topic of a ROS bag: PointStamped fixes or Odometry), with the ARCHE protocol by
// default (estimate interpolated at the reference stamps, x-y-z-yaw alignment), a PNG plot, and
// optionally the accuracy and completeness of a reconstructed mesh against a ground-truth mesh.
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "runner/bag_scan_source.h"
#include "cli/command_line.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/ply_reader.h"
#include "covoxslam/io/rosbag_reader.h"
#include "covoxslam/io/trajectory_io.h"
#include "eval/png_plot.h"
#include "eval/reconstruction_evaluation.h"
#include "eval/trajectory_evaluation.h"

namespace {

using namespace covox;

const char kUsage[] =
    "usage: evaluate_trajectory --reference GT.tum --estimate A.tum[,B.tum...] [options]\n"
    "       evaluate_trajectory --mesh RECONSTRUCTION.ply --gt-mesh WORLD.ply [options]\n"
    "  --labels NAME[,NAME...]   names of the estimates in the table and plot (default: file "
    "names)\n"
    "  --topic T                 trajectory topic of .bag files (default "
    "/penguin/piksi_node/enu_pose_fix)\n"
    "  --align MODE              none | translation | 4dof | se3 | sim3 (default 4dof, as ARCHE)\n"
    "  --max-time-gap-s S        largest gap to an estimate pose to interpolate across (default "
    "0.1)\n"
    "  --rpe-delta D             RPE pair spacing (default 10)\n"
    "  --rpe-unit m|frames       unit of --rpe-delta (default m)\n"
    "  --plot FILE.png           top view and error over time\n"
    "  --thresholds-m T[,T...]   reconstruction thresholds (default 0.1,0.2,0.5)\n"
    "  --sample-spacing-m S      ground-truth surface sampling for completeness (default 0.1)\n";

std::vector<std::string> split_commas(const std::string& text) {
  std::vector<std::string> items;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');) {
    if (!item.empty()) items.push_back(item);
  }
  return items;
}

std::string file_stem(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
  const size_t dot = name.find_last_of('.');
  return dot == std::string::npos ? name : name.substr(0, dot);
}

void evaluate_trajectories(tools::CommandLine& args, const std::string& reference_path,
                           const std::string& estimates_text) {
  eval::TrajectoryEvaluationOptions options;
  options.alignment = eval::parse_alignment_mode(args.text("--align", "4dof"));
  options.association.max_time_gap_s = args.number("--max-time-gap-s", 0.1, 0.0, 3600.0);
  options.relative.delta = args.number("--rpe-delta", 10.0, 1e-6, 1e9);
  options.relative.unit = eval::parse_relative_delta_unit(args.text("--rpe-unit", "m"));
  const std::vector<std::string> estimate_paths = split_commas(estimates_text);
  std::vector<std::string> labels = split_commas(args.text("--labels", ""));
  const std::string plot_path = args.output_file("--plot", "");
  const std::string topic = args.text("--topic", "/penguin/piksi_node/enu_pose_fix");
  args.finish();
  // A .bag is read through its trajectory topic, anything else as a TUM file.
  auto read_trajectory = [&](const std::string& path) {
    if (path.size() > 4 && path.compare(path.size() - 4, 4, ".bag") == 0) {
      io::rosbag::BagReader bag(path);
      return tools::read_bag_trajectory(bag, topic);
    }
    return io::read_tum_trajectory(path);
  };
  if (estimate_paths.empty()) args.fail("--estimate needs at least one file");
  if (labels.empty()) {
    for (const std::string& path : estimate_paths) labels.push_back(file_stem(path));
  }
  if (labels.size() != estimate_paths.size()) {
    args.fail("--labels names " + std::to_string(labels.size()) +
              " estimates but --estimate gives " + std::to_string(estimate_paths.size()));
  }

  const io::Trajectory reference = read_trajectory(reference_path);
  eval::TrajectoryFigure figure;
  figure.top_view_m.push_back({"REFERENCE", eval::Rgb{60, 60, 60}, {}});
  for (const io::StampedPose& pose : reference.poses) {
    figure.top_view_m.back().points.push_back({pose.position_m.x(), pose.position_m.y()});
  }
  const std::string rpe_unit =
      options.relative.unit == eval::RelativeDeltaUnit::kFrames ? " frames" : " m";
  std::printf("reference: %s (%zu poses); alignment %s; RPE over %g%s\n", reference_path.c_str(),
              reference.size(), eval::alignment_mode_name(options.alignment).c_str(),
              options.relative.delta, rpe_unit.c_str());
  std::printf("%-16s %8s %10s %10s %10s %10s %12s %12s\n", "estimate", "matched", "ATE rmse",
              "ATE mean", "ATE median", "ATE max", "RPE rmse m", "RPE rmse deg");
  const double start_s = reference.empty() ? 0.0 : reference.poses.front().timestamp_s;
  for (size_t k = 0; k < estimate_paths.size(); ++k) {
    const io::Trajectory estimate = read_trajectory(estimate_paths[k]);
    const eval::TrajectoryEvaluation evaluation =
        eval::evaluate_trajectory(reference, estimate, options);
    const eval::ErrorStatistics& ate = evaluation.absolute_position_m;
    const eval::RelativePoseError& rpe = evaluation.relative;
    std::printf("%-16s %8zu %10.4f %10.4f %10.4f %10.4f %12.4f %12s\n", labels[k].c_str(),
                ate.count, ate.rmse, ate.mean, ate.median, ate.max, rpe.translation_m.rmse,
                rpe.has_rotation ? std::to_string(rpe.rotation_deg.rmse).c_str() : "-");
    const eval::Rgb colour = eval::series_colour(k);
    eval::PlotSeries top{labels[k], colour, {}};
    eval::PlotSeries error{labels[k], colour, {}};
    for (size_t i = 0; i < evaluation.aligned.size(); ++i) {
      const Eigen::Vector3d& p = evaluation.aligned.estimate_positions_m[i];
      top.points.push_back({p.x(), p.y()});
      error.points.push_back(
          {evaluation.aligned.timestamps_s[i] - start_s, evaluation.position_errors_m[i]});
    }
    figure.top_view_m.push_back(std::move(top));
    figure.error_over_time.push_back(std::move(error));
  }
  if (!plot_path.empty()) {
    eval::write_png(plot_path, eval::render_trajectory_figure(figure));
    std::printf("plot: %s\n", plot_path.c_str());
  }
}

void evaluate_mesh(tools::CommandLine& args, const std::string& mesh_path,
                   const std::string& truth_path) {
  eval::ReconstructionEvaluationOptions options;
  options.thresholds_m = args.numbers("--thresholds-m", {0.1, 0.2, 0.5}, 1e-6, 1000.0);
  options.sample_spacing_m = args.number("--sample-spacing-m", 0.1, 0.001, 100.0);
  args.finish();
  const map::Mesh reconstruction = io::read_mesh_ply(mesh_path);
  const map::Mesh truth = io::read_mesh_ply(truth_path);
  const eval::ReconstructionEvaluation evaluation =
      eval::evaluate_reconstruction(reconstruction, truth, options);
  eval::print_reconstruction_evaluation(std::cout, evaluation);
}

}  // namespace

int main(int argc, char** argv) {
  tools::CommandLine args(argc, argv, kUsage);
  try {
    const std::string reference = args.text("--reference", "");
    const std::string estimates = args.text("--estimate", "");
    const std::string mesh = args.text("--mesh", "");
    const std::string truth_mesh = args.text("--gt-mesh", "");
    if (!reference.empty() || !estimates.empty()) {
      if (reference.empty() || estimates.empty())
        args.fail("--reference and --estimate go together");
      if (!mesh.empty() || !truth_mesh.empty())
        args.fail("evaluate trajectories or a mesh, not both at once");
      evaluate_trajectories(args, reference, estimates);
    } else if (!mesh.empty() && !truth_mesh.empty()) {
      evaluate_mesh(args, mesh, truth_mesh);
    } else {
      args.fail("give --reference and --estimate, or --mesh and --gt-mesh");
    }
  } catch (const Error& error) {
    std::cerr << "evaluate_trajectory: " << error.what() << std::endl;
    return 1;
  }
  return 0;
}
