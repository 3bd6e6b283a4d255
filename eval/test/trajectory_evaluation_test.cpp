// The trajectory evaluation recovers errors that were put in on purpose: a constant offset, a
// rotation, a scale, a per-step error; the PNG writer produces a valid file; and the exact
// point-to-mesh distance search behind the reconstruction evaluation agrees with brute force.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#if COVOX_HAVE_ZLIB
#include <zlib.h>
#endif

#include "covoxslam/core/error.h"
#include "eval/mesh_distance.h"
#include "eval/png_plot.h"
#include "eval/reconstruction_evaluation.h"
#include "sim/sim_world.h"
#include "eval/trajectory_evaluation.h"

namespace covox {
namespace eval {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A wavy 3-D loop (not planar, so a rotation about any axis is observable), one pose per 0.1 s.
io::Trajectory reference_loop(int count = 400) {
  io::Trajectory trajectory;
  for (int i = 0; i < count; ++i) {
    const double t = 0.1 * i;
    const double a = 2.0 * kPi * i / count;
    io::StampedPose pose;
    pose.timestamp_s = 100.0 + t;
    pose.position_m =
        Eigen::Vector3d(20.0 * std::sin(a), 10.0 * std::sin(2.0 * a), 2.0 + std::sin(3.0 * a));
    pose.orientation =
        Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()) *
                           Eigen::AngleAxisd(0.1 * std::sin(a), Eigen::Vector3d::UnitX()));
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

// Applies p -> scale * R p + t (and R to orientations) to every pose.
io::Trajectory transformed(const io::Trajectory& input, const Eigen::Matrix3d& rotation,
                           const Eigen::Vector3d& translation_m, double scale = 1.0) {
  io::Trajectory output = input;
  for (io::StampedPose& pose : output.poses) {
    pose.position_m = scale * (rotation * pose.position_m) + translation_m;
    pose.orientation = Eigen::Quaterniond(rotation) * pose.orientation;
  }
  return output;
}

TrajectoryEvaluation evaluate(const io::Trajectory& reference, const io::Trajectory& estimate,
                              AlignmentMode mode) {
  TrajectoryEvaluationOptions options;
  options.alignment = mode;
  return evaluate_trajectory(reference, estimate, options);
}

TEST(TrajectoryEvaluation, ConstantOffsetIsMeasuredWithoutAlignmentAndRemovedWithIt) {
  const io::Trajectory reference = reference_loop();
  const Eigen::Vector3d offset(0.3, -0.4, 1.2);  // |offset| = 1.3 m
  const io::Trajectory estimate = transformed(reference, Eigen::Matrix3d::Identity(), offset);
  const TrajectoryEvaluation none = evaluate(reference, estimate, AlignmentMode::kNone);
  EXPECT_EQ(none.absolute_position_m.count, reference.size());
  EXPECT_NEAR(none.absolute_position_m.rmse, 1.3, 1e-9);
  EXPECT_NEAR(none.absolute_position_m.max, 1.3, 1e-9);
  for (AlignmentMode mode : {AlignmentMode::kTranslation, AlignmentMode::kTranslationYaw,
                             AlignmentMode::kSe3, AlignmentMode::kSim3}) {
    EXPECT_LT(evaluate(reference, estimate, mode).absolute_position_m.rmse, 1e-9)
        << alignment_mode_name(mode);
  }
}

TEST(TrajectoryEvaluation, YawAndFullRotationsAreRemovedByTheirAlignments) {
  const io::Trajectory reference = reference_loop();
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const io::Trajectory yawed = transformed(reference, yaw, Eigen::Vector3d(5.0, -3.0, 0.5));
  EXPECT_LT(evaluate(reference, yawed, AlignmentMode::kTranslationYaw).absolute_position_m.rmse,
            1e-9);
  EXPECT_GT(evaluate(reference, yawed, AlignmentMode::kTranslation).absolute_position_m.rmse, 1.0);

  const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitY()) *
                                Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ()))
                                   .toRotationMatrix();
  const io::Trajectory rotated = transformed(reference, tilt, Eigen::Vector3d(1.0, 2.0, 3.0));
  const TrajectoryEvaluation se3 = evaluate(reference, rotated, AlignmentMode::kSe3);
  EXPECT_LT(se3.absolute_position_m.rmse, 1e-9);
  // The recovered transform is the inverse of the one applied.
  EXPECT_LT((se3.alignment.rotation * tilt - Eigen::Matrix3d::Identity()).norm(), 1e-9);
  EXPECT_NEAR(se3.alignment.scale, 1.0, 1e-12);
  // Yaw-only alignment cannot remove a tilt.
  EXPECT_GT(evaluate(reference, rotated, AlignmentMode::kTranslationYaw).absolute_position_m.rmse,
            0.5);
  // After SE(3) alignment, orientations agree too: the rotational RPE vanishes.
  EXPECT_LT(se3.relative.rotation_deg.max, 1e-6);
}

TEST(TrajectoryEvaluation, ScaleIsRemovedOnlyBySim3) {
  const io::Trajectory reference = reference_loop();
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const io::Trajectory scaled =
      transformed(reference, rotation, Eigen::Vector3d(0.0, 4.0, 0.0), 1.25);
  const TrajectoryEvaluation sim3 = evaluate(reference, scaled, AlignmentMode::kSim3);
  EXPECT_LT(sim3.absolute_position_m.rmse, 1e-9);
  EXPECT_NEAR(sim3.alignment.scale, 1.0 / 1.25, 1e-9);
  EXPECT_GT(evaluate(reference, scaled, AlignmentMode::kSe3).absolute_position_m.rmse, 1.0);
}

TEST(TrajectoryEvaluation, EstimateIsInterpolatedAtReferenceStamps) {
  // The estimate is the reference sampled every other pose and shifted by half a period in time
  // on a straight line at constant speed: interpolation must give the reference back exactly.
  io::Trajectory reference, estimate;
  for (int i = 0; i < 100; ++i) {
    io::StampedPose pose;
    pose.timestamp_s = 0.1 * i;
    pose.position_m = Eigen::Vector3d(2.0 * pose.timestamp_s, 1.0, 0.5 * pose.timestamp_s);
    reference.poses.push_back(pose);
    if (i % 2 == 0) {
      pose.timestamp_s += 0.05;
      pose.position_m = Eigen::Vector3d(2.0 * pose.timestamp_s, 1.0, 0.5 * pose.timestamp_s);
      estimate.poses.push_back(pose);
    }
  }
  const TrajectoryEvaluation evaluation = evaluate(reference, estimate, AlignmentMode::kNone);
  EXPECT_LT(evaluation.absolute_position_m.max, 1e-9);
  // The first stamp precedes the estimate, the last follows it.
  EXPECT_EQ(evaluation.aligned.skipped_outside_range, 2u);
  EXPECT_EQ(evaluation.absolute_position_m.count, 98u);
}

TEST(TrajectoryEvaluation, RelativePoseErrorOfAKnownPerStepError) {
  // Straight flight along x; the estimate moves 1.05 m where the truth moves 1 m, so every
  // 1-frame RPE is 0.05 m and every 10-frame RPE 0.5 m, while the ATE grows along the line.
  io::Trajectory reference, estimate;
  for (int i = 0; i < 50; ++i) {
    io::StampedPose pose;
    pose.timestamp_s = i;
    pose.position_m = Eigen::Vector3d(i, 0.0, 0.0);
    reference.poses.push_back(pose);
    pose.position_m = Eigen::Vector3d(1.05 * i, 0.0, 0.0);
    estimate.poses.push_back(pose);
  }
  AssociationOptions association;
  association.max_time_gap_s = 0.5;
  const AssociatedTrajectories associated =
      associate_by_interpolation(reference, estimate, association);
  RelativePoseErrorOptions options;
  options.unit = RelativeDeltaUnit::kFrames;
  options.delta = 1;
  RelativePoseError rpe = compute_relative_pose_error(associated, options);
  EXPECT_EQ(rpe.translation_m.count, 49u);
  EXPECT_NEAR(rpe.translation_m.rmse, 0.05, 1e-9);
  EXPECT_NEAR(rpe.rotation_deg.max, 0.0, 1e-9);
  options.unit = RelativeDeltaUnit::kMetres;
  options.delta = 10.0;
  rpe = compute_relative_pose_error(associated, options);
  EXPECT_EQ(rpe.translation_m.count, 40u);
  EXPECT_NEAR(rpe.translation_m.mean, 0.5, 1e-9);
}

TEST(TrajectoryEvaluation, TooFewAssociatedPosesIsAClearError) {
  io::Trajectory reference = reference_loop(10);
  io::Trajectory estimate = reference_loop(10);
  for (io::StampedPose& pose : estimate.poses) pose.timestamp_s += 1000.0;  // another clock
  EXPECT_THROW(evaluate(reference, estimate, AlignmentMode::kSe3), Error);
  EXPECT_THROW(parse_alignment_mode("affine"), Error);
}

TEST(ErrorStatistics, MedianOfEvenAndOddCounts) {
  EXPECT_DOUBLE_EQ(compute_error_statistics({3.0, 1.0, 2.0}).median, 2.0);
  EXPECT_DOUBLE_EQ(compute_error_statistics({4.0, 1.0, 3.0, 2.0}).median, 2.5);
  EXPECT_EQ(compute_error_statistics({}).count, 0u);
}

TEST(PngPlot, ChecksumsMatchKnownValuesAndTheFileIsWellFormed) {
  const char* text = "123456789";
  // The standard check values of CRC-32 and Adler-32 for "123456789".
  EXPECT_EQ(crc32(reinterpret_cast<const uint8_t*>(text), 9), 0xCBF43926u);
  EXPECT_EQ(adler32(reinterpret_cast<const uint8_t*>(text), 9), 0x091E01DEu);

  TrajectoryFigure figure;
  figure.top_view_m.push_back({"TRUTH", series_colour(0), {{0, 0}, {10, 5}, {20, 0}}});
  figure.error_over_time.push_back({"ODOMETRY", series_colour(1), {{0, 0}, {1, 0.5}, {2, 0.2}}});
  const RgbImage image = render_trajectory_figure(figure, 400);
  const std::vector<uint8_t> png = encode_png(image);
  ASSERT_GT(png.size(), 8u + 25u);
  EXPECT_EQ(std::memcmp(png.data(), "\x89PNG\r\n\x1a\n", 8), 0);
  EXPECT_EQ(std::memcmp(png.data() + 12, "IHDR", 4), 0);
  // The image holds the series colour somewhere (the line was drawn).
  bool found = false;
  for (int y = 0; y < image.height_px() && !found; ++y)
    for (int x = 0; x < image.width_px() && !found; ++x)
      found = image.pixel(x, y) == series_colour(0);
  EXPECT_TRUE(found);
}

#if !COVOX_HAVE_ZLIB
// The data of a zlib stream of stored blocks (BTYPE 00), read back as RFC 1950/1951 define them;
// empty when a block is of another type or malformed.
std::vector<uint8_t> read_stored_blocks(const std::vector<uint8_t>& stream) {
  std::vector<uint8_t> data;
  size_t at = 2;  // after the zlib header
  for (bool last = false; !last;) {
    if (at + 5 > stream.size() || (stream[at] & 0x06) != 0) return {};
    last = (stream[at] & 1) != 0;
    const size_t length = stream[at + 1] | (stream[at + 2] << 8);
    const size_t complement = stream[at + 3] | (stream[at + 4] << 8);
    if ((length ^ 0xFFFF) != complement || at + 5 + length > stream.size()) return {};
    data.insert(data.end(), stream.begin() + at + 5, stream.begin() + at + 5 + length);
    at += 5 + length;
  }
  return data;
}
#endif

TEST(PngPlot, TheImageDataIsTheFilteredScanlinesAndItsStreamInflatesBack) {
  TrajectoryFigure figure;
  figure.top_view_m.push_back({"TRUTH", series_colour(0), {{0, 0}, {10, 5}, {20, 0}}});
  figure.error_over_time.push_back({"ODOMETRY", series_colour(1), {{0, 0}, {1, 0.5}, {2, 0.2}}});
  const RgbImage image = render_trajectory_figure(figure, 400);
  const std::vector<uint8_t> raw = png_scanlines(image);
  const size_t row_bytes = 3 * static_cast<size_t>(image.width_px()) + 1;
  ASSERT_EQ(raw.size(), row_bytes * image.height_px());
  for (int y = 0; y < image.height_px(); ++y) {
    ASSERT_EQ(raw[y * row_bytes], 0) << "row " << y << " must use filter type 0";
    for (int x = 0; x < image.width_px(); x += 37) {
      const uint8_t* pixel = &raw[y * row_bytes + 1 + 3 * x];
      ASSERT_EQ(Rgb({pixel[0], pixel[1], pixel[2]}), image.pixel(x, y)) << x << ", " << y;
    }
  }
  const std::vector<uint8_t> stream = zlib_stream(raw);
  ASSERT_GE(stream.size(), 6u);
  EXPECT_EQ(((stream[0] << 8) | stream[1]) % 31, 0) << "the zlib header check";
#if COVOX_HAVE_ZLIB
  std::vector<uint8_t> inflated(raw.size());
  uLongf size = static_cast<uLongf>(inflated.size());
  ASSERT_EQ(uncompress(inflated.data(), &size, stream.data(), static_cast<uLong>(stream.size())),
            Z_OK);
  EXPECT_EQ(size, raw.size());
  EXPECT_EQ(inflated, raw);
  // A plot is mostly flat colour: deflate keeps a small part of it.
  EXPECT_LT(stream.size(), raw.size() / 10);
#else
  EXPECT_EQ(read_stored_blocks(stream), raw);
  const uint32_t adler = adler32(raw.data(), raw.size());
  EXPECT_EQ(stream[stream.size() - 4], adler >> 24);
  EXPECT_EQ(stream[stream.size() - 1], adler & 0xFF);
#endif
  // encode_png's IDAT chunk, after the signature (8 bytes) and the IHDR chunk (25), is that stream.
  const std::vector<uint8_t> png = encode_png(image);
  ASSERT_GT(png.size(), 33u + 8u);
  EXPECT_EQ(std::memcmp(png.data() + 33 + 4, "IDAT", 4), 0);
  const size_t idat_length =
      (static_cast<size_t>(png[33]) << 24) | (png[34] << 16) | (png[35] << 8) | png[36];
  EXPECT_EQ(std::vector<uint8_t>(png.begin() + 41, png.begin() + 41 + idat_length), stream);
}

TEST(ReconstructionEvaluation, ExactAndShiftedSurfacesScoreAsExpected) {
  sim::World world;
  sim::Box box;
  box.half_extent_m = Eigen::Vector3d(2.0, 1.5, 1.0);
  world.add(box);
  const map::Mesh truth = world.to_mesh();
  ReconstructionEvaluationOptions options;
  options.thresholds_m = {0.1, 0.2};
  options.sample_spacing_m = 0.05;
  const ReconstructionEvaluation exact = evaluate_reconstruction(truth, truth, options);
  EXPECT_NEAR(exact.truth_area_m2, 2.0 * (4.0 * 3.0 + 4.0 * 2.0 + 3.0 * 2.0), 1e-6);
  EXPECT_DOUBLE_EQ(exact.accuracy_fraction[0], 1.0);
  EXPECT_NEAR(exact.completeness_fraction[0], 1.0, 1e-9);
  // Shifted by 0.15 m along z: the top and bottom faces are 0.15 m off, the side faces overlap.
  map::Mesh shifted = truth;
  for (Vec3f& v : shifted.vertices_m) v.z += 0.15f;
  const ReconstructionEvaluation moved = evaluate_reconstruction(shifted, truth, options);
  EXPECT_NEAR(moved.accuracy_fraction[1], 1.0, 1e-9);
  EXPECT_LT(moved.accuracy_fraction[0], 1.0);
  // At 0.1 m, top and bottom (2 x 12 m^2 of 52 m^2) are missing, except a 0.1 m rim of the top
  // that the raised side faces reach (14 m of perimeter x 0.1 m); the lowest 0.05 m of the side
  // faces are missing too (14 m x 0.05 m).
  EXPECT_NEAR(moved.completeness_fraction[0], (52.0 - 24.0 + 1.4 - 0.7) / 52.0, 0.003);
  EXPECT_NEAR(moved.completeness_fraction[1], 1.0, 1e-9);
}

// The grid search must give what testing every triangle gives, up to the radius, and infinity
// beyond it; small cells against a larger radius make queries cross several shells of cells.
TEST(MeshDistance, MatchesBruteForceWithinTheRadiusAndIsInfiniteBeyond) {
  std::mt19937 random(7);
  std::uniform_real_distribution<float> coordinate(-2.0f, 2.0f), offset(-0.4f, 0.4f);
  map::Mesh mesh;
  for (uint32_t t = 0; t < 200; ++t) {
    const Vec3f corner(coordinate(random), coordinate(random), coordinate(random));
    for (int k = 0; k < 3; ++k) {
      mesh.vertices_m.emplace_back(corner.x + offset(random), corner.y + offset(random),
                                   corner.z + offset(random));
      mesh.triangles.push_back(3 * t + k);
    }
  }
  const MeshDistance distance(mesh, 0.15);
  const double radius_m = 0.6;
  std::uniform_real_distribution<double> query(-3.0, 3.0);
  int near = 0, far = 0;
  for (int q = 0; q < 2000; ++q) {
    const Eigen::Vector3d p(query(random), query(random), query(random));
    double brute_force_m = std::numeric_limits<double>::infinity();
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const auto corner = [&](int k) {
        const Vec3f& v = mesh.vertices_m[mesh.triangles[3 * t + k]];
        return Eigen::Vector3d(v.x, v.y, v.z);
      };
      brute_force_m =
          std::min(brute_force_m,
                   (closest_point_on_triangle(p, corner(0), corner(1), corner(2)) - p).norm());
    }
    const double found_m = distance.distance_m(p, radius_m);
    if (brute_force_m <= radius_m) {
      ++near;
      ASSERT_NEAR(found_m, brute_force_m, 1e-12) << "query " << q;
    } else {
      ++far;
      ASSERT_TRUE(std::isinf(found_m))
          << "query " << q << ": " << found_m << " m, truly " << brute_force_m << " m";
    }
  }
  EXPECT_GT(near, 200);  // both branches were exercised
  EXPECT_GT(far, 200);
}

TEST(MeshDistance, MeshWithoutTrianglesIsAPointSetAndBadInputsAreClearErrors) {
  map::Mesh points;
  points.vertices_m = {Vec3f(0.0f, 0.0f, 0.0f), Vec3f(1.0f, 0.0f, 0.0f)};
  const MeshDistance distance(points, 0.5);
  EXPECT_EQ(distance.element_count(), 2u);
  EXPECT_NEAR(distance.distance_m(Eigen::Vector3d(0.9, 0.3, 0.0), 1.0), std::hypot(0.1, 0.3), 1e-7);
  EXPECT_TRUE(std::isinf(distance.distance_m(Eigen::Vector3d(0.5, 2.0, 0.0), 1.0)));
  EXPECT_THROW(MeshDistance(points, 0.0), Error);
  EXPECT_THROW(distance.distance_m(Eigen::Vector3d::Zero(), -1.0), Error);
  EXPECT_THROW(distance.distance_m(Eigen::Vector3d::Zero(), 1e6), Error);  // far too many cells
  EXPECT_THROW(distance.distance_m(Eigen::Vector3d::Constant(std::nan("")), 1.0), Error);
  map::Mesh broken = points;
  broken.triangles = {0, 1, 5};
  EXPECT_THROW(MeshDistance(broken, 0.5), Error);
}

}  // namespace
}  // namespace eval
}  // namespace covox
