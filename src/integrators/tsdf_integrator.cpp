#include "covoxslam/integrators/tsdf_integrator.h"

#include <cmath>
#include <string>

#include "covoxslam/core/error.h"
#include "covoxslam/core/log.h"
#include "covoxslam/core/radix_sort.h"
#include "covoxslam/core/stage_profiler.h"
#include "covoxslam/integrators/internal/tsdf_frame_strategy.h"
#include "covoxslam/integrators/internal/tsdf_integrator_ops.h"

namespace covox::integrators {

namespace {
void require(bool condition, const std::string& message) {
  if (!condition) throw Error("TSDF integrator: " + message);
}
}  // namespace

namespace tsdf {

FrameKeyCodec make_frame_key_codec(const Index3D& min_voxel, const Index3D& max_voxel,
                                   int32_t voxels_per_side) {
  FrameKeyCodec codec;
  codec.voxels_per_side = voxels_per_side;
  codec.voxel_bits =
      bits_for(static_cast<uint64_t>(voxels_per_side) * voxels_per_side * voxels_per_side - 1);
  const Index3D low(floor_divide(min_voxel.x, voxels_per_side) - 1,
                    floor_divide(min_voxel.y, voxels_per_side) - 1,
                    floor_divide(min_voxel.z, voxels_per_side) - 1);
  const Index3D high(floor_divide(max_voxel.x, voxels_per_side) + 1,
                     floor_divide(max_voxel.y, voxels_per_side) + 1,
                     floor_divide(max_voxel.z, voxels_per_side) + 1);
  codec.origin_block = low;
  const int64_t sx = int64_t(high.x) - low.x + 1, sy = int64_t(high.y) - low.y + 1,
                sz = int64_t(high.z) - low.z + 1;
  const double blocks = double(sx) * double(sy) * double(sz);
  if (!(blocks * double(uint64_t(1) << codec.voxel_bits) < 4.0e18)) {
    throw Error("TSDF integrator: the frame spans " + std::to_string(sx) + " x " +
                std::to_string(sy) + " x " + std::to_string(sz) +
                " blocks, too many for 64-bit update keys; lower max_ray_length_m");
  }
  codec.size_x = static_cast<int32_t>(sx);
  codec.size_y = static_cast<int32_t>(sy);
  codec.size_z = static_cast<int32_t>(sz);
  codec.out_of_range_key = static_cast<uint64_t>(sx * sy * sz) << codec.voxel_bits;
  codec.zero_weight_key = codec.out_of_range_key + 1;
  codec.key_bits = bits_for(codec.zero_weight_key);
  return codec;
}

MergeKeys make_merge_keys(const Vec3f& origin, float max_ray_length_m, float voxel_size_m,
                          int32_t voxels_per_side) {
  // Every surface point lies within max_ray_length_m of the origin (make_ray drops the others);
  // one voxel more on each side absorbs the rounding of the world transform.
  const float inverse_voxel_size = 1.0f / voxel_size_m;
  const Vec3f reach(max_ray_length_m, max_ray_length_m, max_ray_length_m);
  const Index3D low = voxel_of(origin - reach, inverse_voxel_size);
  const Index3D high = voxel_of(origin + reach, inverse_voxel_size);
  MergeKeys keys;
  keys.codec = make_frame_key_codec(Index3D(low.x - 1, low.y - 1, low.z - 1),
                                    Index3D(high.x + 1, high.y + 1, high.z + 1), voxels_per_side);
  return keys;
}

}  // namespace tsdf

TsdfIntegrationMethod parse_tsdf_integration_method(const std::string& name) {
  if (name == "simple") return TsdfIntegrationMethod::kSimple;
  if (name == "merged") return TsdfIntegrationMethod::kMerged;
  throw Error("TSDF integrator: unknown method '" + name + "' (expected simple or merged)");
}

const char* to_string(TsdfIntegrationMethod method) {
  return method == TsdfIntegrationMethod::kSimple ? "simple" : "merged";
}

void validate(const TsdfIntegratorConfig& c, float voxel_size_m) {
  require(std::isfinite(c.truncation_distance_m) && c.truncation_distance_m > 0.0f,
          "truncation_distance_m must be positive, got " + std::to_string(c.truncation_distance_m));
  require(c.truncation_distance_m >= voxel_size_m,
          "truncation_distance_m (" + std::to_string(c.truncation_distance_m) +
              ") must be at least one voxel (" + std::to_string(voxel_size_m) + " m)");
  require(c.max_weight > 0.0f, "max_weight must be positive, got " + std::to_string(c.max_weight));
  require(c.min_ray_length_m >= 0.0f,
          "min_ray_length_m must be >= 0, got " + std::to_string(c.min_ray_length_m));
  require(c.max_ray_length_m > c.min_ray_length_m,
          "max_ray_length_m (" + std::to_string(c.max_ray_length_m) +
              ") must exceed min_ray_length_m (" + std::to_string(c.min_ray_length_m) + ")");
  require(
      c.method != TsdfIntegrationMethod::kMerged || c.max_ray_length_m <= tsdf::kMaxMergedRange_m,
      "max_ray_length_m (" + std::to_string(c.max_ray_length_m) + ") must be at most " +
          std::to_string(tsdf::kMaxMergedRange_m) +
          " m with the merged method (use simple beyond)");
  require(!c.use_sparsity_compensation_factor || c.sparsity_compensation_factor > 0.0f,
          "sparsity_compensation_factor must be positive, got " +
              std::to_string(c.sparsity_compensation_factor));
  require(
      c.fixed_point_sums_max_scratch_mb >= 0 && c.fixed_point_sums_max_scratch_mb <= (1 << 20),
      "fixed_point_sums_max_scratch_mb must be in [0, 1048576] (0: never sum every visit), got " +
          std::to_string(c.fixed_point_sums_max_scratch_mb));
}

struct TsdfIntegrator::Scratch {
  explicit Scratch(Device device) : buffers(device) {}
  TsdfScratchBuffers buffers;
};

namespace tsdf {
void IntegratorInternals::set_strategy(TsdfIntegrator& integrator, const FrameStrategy& strategy) {
  integrator.strategy_ = std::make_unique<FrameStrategy>(strategy);
}
const FrameStrategy& IntegratorInternals::strategy(const TsdfIntegrator& integrator) {
  static const FrameStrategy shipped;
  return integrator.strategy_ ? *integrator.strategy_ : shipped;
}
}  // namespace tsdf

TsdfIntegrator::TsdfIntegrator(const TsdfIntegratorConfig& config) : config_(config) {}
TsdfIntegrator::~TsdfIntegrator() = default;
TsdfIntegrator::TsdfIntegrator(TsdfIntegrator&&) noexcept = default;
TsdfIntegrator& TsdfIntegrator::operator=(TsdfIntegrator&&) noexcept = default;

namespace {
void check_pose(const Eigen::Isometry3d& T_map_sensor) {
  if (!T_map_sensor.matrix().allFinite()) {
    throw Error("TSDF integrator: the sensor pose is not finite; the cloud was not integrated");
  }
}

// Logs dropped input once per call, so a bad sensor shows up without flooding the log.
void log_drops(const IntegrationStats& stats) {
  if (stats.dropped_non_finite > 0 || stats.voxels_out_of_range > 0) {
    log_warning("TSDF integrator: dropped ", stats.dropped_non_finite, " non-finite points of ",
                stats.points_in, "; ", stats.voxels_out_of_range,
                " voxel updates outside the map's key range");
  }
}
}  // namespace

IntegrationStats TsdfIntegrator::integrate(map::TsdfMap& map, const PointCloudView& cloud,
                                           const Eigen::Isometry3d& T_map_sensor,
                                           const Stream& stream) {
  validate(config_, map.voxel_size_m());
  if (cloud.intensities && !(cloud.intensity_max_value > 0.0f)) {
    throw Error("TSDF integrator: intensity_max_value must be positive");
  }
  check_pose(T_map_sensor);
  if (!scratch_ || scratch_->buffers.device() != map.device()) {
    scratch_ = std::make_unique<Scratch>(map.device());
  }
  const IntegrationStats stats = dispatch(map.device(), [&](auto backend) {
    return tsdf_integrate_points(backend, config_, tsdf::IntegratorInternals::strategy(*this), map,
                                 cloud, T_map_sensor, scratch_->buffers, stream);
  });
  log_drops(stats);
  return stats;
}

IntegrationStats TsdfIntegrator::integrate(map::TsdfMap& map, const std::vector<Vec3f>& points,
                                           const std::vector<Rgb8>& colors,
                                           const Eigen::Isometry3d& T_map_sensor) {
  if (!colors.empty() && colors.size() != points.size()) {
    throw Error("TSDF integrator: " + std::to_string(colors.size()) + " colours for " +
                std::to_string(points.size()) + " points");
  }
  const Stream stream(map.device());
  if (!scratch_ || scratch_->buffers.device() != map.device()) {
    scratch_ = std::make_unique<Scratch>(map.device());
  }
  scratch_->buffers.input.points.copy_from_host(points, stream);
  scratch_->buffers.input.colors.copy_from_host(colors, stream);
  PointCloudView view;
  view.points = scratch_->buffers.input.points.data();
  view.colors = colors.empty() ? nullptr : scratch_->buffers.input.colors.data();
  view.count = static_cast<int64_t>(points.size());
  return integrate(map, view, T_map_sensor, stream);
}

IntegrationStats TsdfIntegrator::integrate_depth(map::TsdfMap& map, const DepthImageView& image,
                                                 const Eigen::Isometry3d& T_map_camera,
                                                 const Stream& stream) {
  const PinholeIntrinsics& k = image.intrinsics;
  if (k.width <= 0 || k.height <= 0 || !(k.fx > 0.0f) || !(k.fy > 0.0f)) {
    throw Error("TSDF integrator: invalid camera intrinsics (width " + std::to_string(k.width) +
                ", height " + std::to_string(k.height) + ", fx " + std::to_string(k.fx) + ", fy " +
                std::to_string(k.fy) + ")");
  }
  if (!image.depth && !image.depth_m) throw Error("TSDF integrator: the depth image has no data");
  if (!image.depth_m && !(image.depth_units_per_m > 0.0f)) {
    throw Error("TSDF integrator: depth_units_per_m must be positive");
  }
  validate(config_, map.voxel_size_m());
  check_pose(T_map_camera);
  if (!scratch_ || scratch_->buffers.device() != map.device()) {
    scratch_ = std::make_unique<Scratch>(map.device());
  }
  tsdf::DepthImagePoints points;
  points.depth = image.depth;
  points.depth_m = image.depth_m;
  points.colors = image.colors;
  points.metres_per_unit = 1.0f / image.depth_units_per_m;
  points.invalid_value = image.invalid_value;
  points.inverse_fx = 1.0f / k.fx;
  points.inverse_fy = 1.0f / k.fy;
  points.cx = k.cx;
  points.cy = k.cy;
  points.width = k.width;
  points.height = k.height;
  // (the points and colours in tile order: tsdf::pixel_tile_order, tsdf_kernels.h)
  const IntegrationStats stats = dispatch(map.device(), [&](auto backend) {
    return tsdf_integrate_depth_image(backend, config_, tsdf::IntegratorInternals::strategy(*this),
                                      map, points, T_map_camera, scratch_->buffers, stream);
  });
  log_drops(stats);
  return stats;
}

}  // namespace covox::integrators
