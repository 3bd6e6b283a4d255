#include "covoxslam/integrators/esdf_queries.h"

#include <cmath>

#include "covoxslam/core/device_algorithms.h"
#include "covoxslam/core/error.h"
#include "covoxslam/integrators/internal/esdf_queries_ops.h"

namespace covox::integrators {
namespace {

// Queries only read the map; the views are non-const because kernels share one view type.
EsdfLookup make_lookup(const map::TsdfMap& map) {
  auto& mutable_map = const_cast<map::TsdfMap&>(map);
  return EsdfLookup{map::BlockVoxelIndexer{map.blocks().device_view(), map.voxels_per_side()},
                    mutable_map.esdf().view(), map.voxel_size_m()};
}

std::vector<SlicePoint> collect_slice(const map::TsdfMap& map, int32_t layer_min, int32_t layer_max,
                                      float z_m, const Stream& stream) {
  auto& mutable_map = const_cast<map::TsdfMap&>(map);
  Buffer<Index3D> block_indices(map.device());
  Buffer<uint32_t> block_slots(map.device());
  map.blocks().export_entries(&block_indices, &block_slots);
  Buffer<uint64_t> columns(map.device());
  Buffer<float> distances(map.device());
  const int64_t count = dispatch(map.device(), [&](auto backend) {
    return esdf_collect_layer(backend, mutable_map.esdf().view(), block_indices.data(),
                              block_slots.data(), static_cast<int64_t>(block_indices.size()),
                              map.voxels_per_side(), layer_min, layer_max, &columns, &distances,
                              stream);
  });
  auto host_columns = columns.to_host(stream);
  auto host_distances = distances.to_host(stream);
  std::vector<SlicePoint> slice(static_cast<size_t>(count));
  const float voxel = map.voxel_size_m();
  for (int64_t i = 0; i < count; ++i) {
    int32_t x = 0, y = 0;
    esdf_column_of_key(host_columns[i], &x, &y);
    slice[i].position_m = Vec3f((x + 0.5f) * voxel, (y + 0.5f) * voxel, z_m);
    slice[i].distance_m = host_distances[i];
  }
  return slice;
}

}  // namespace

void query_esdf(const map::TsdfMap& map, const Vec3f* points_m, int64_t count, EsdfSample* samples,
                const Stream& stream) {
  const EsdfLookup lookup = make_lookup(map);
  dispatch(map.device(), [&](auto backend) {
    esdf_query_points(backend, lookup, points_m, count, samples, stream);
  });
}

std::vector<EsdfSample> query_esdf(const map::TsdfMap& map, const std::vector<Vec3f>& points_m) {
  const Stream stream(map.device());
  auto points = Buffer<Vec3f>::from_host(map.device(), points_m, stream);
  Buffer<EsdfSample> samples(map.device(), points_m.size());
  query_esdf(map, points.data(), static_cast<int64_t>(points_m.size()), samples.data(), stream);
  return samples.to_host(stream);
}

std::vector<SlicePoint> esdf_slice(const map::TsdfMap& map, float z_m, const Stream& stream) {
  const int32_t layer = static_cast<int32_t>(std::floor(z_m / map.voxel_size_m()));
  return collect_slice(map, layer, layer, (layer + 0.5f) * map.voxel_size_m(), stream);
}

std::vector<SlicePoint> esdf_squashed_slice(const map::TsdfMap& map, float z_min_m, float z_max_m,
                                            const Stream& stream) {
  if (!(z_max_m >= z_min_m)) {
    throw Error("esdf_squashed_slice: z_max_m (" + std::to_string(z_max_m) +
                ") is below z_min_m (" + std::to_string(z_min_m) + ")");
  }
  const int32_t layer_min = static_cast<int32_t>(std::floor(z_min_m / map.voxel_size_m()));
  const int32_t layer_max = static_cast<int32_t>(std::floor(z_max_m / map.voxel_size_m()));
  return collect_slice(map, layer_min, layer_max, 0.5f * (z_min_m + z_max_m), stream);
}

std::vector<SlicePoint> esdf_voxels_within(const map::TsdfMap& map, float max_distance_m,
                                           const Stream& stream) {
  auto& mutable_map = const_cast<map::TsdfMap&>(map);
  Buffer<Index3D> block_indices(map.device());
  Buffer<uint32_t> block_slots(map.device());
  map.blocks().export_entries(&block_indices, &block_slots);
  const int32_t side = map.voxels_per_side();
  const int64_t blocks = static_cast<int64_t>(block_indices.size());
  const int64_t total = blocks * side * side * side;
  if (total == 0) return {};
  // Flag, scan for each voxel's place in the output, gather.
  Buffer<uint32_t> flags(map.device(), total);
  Buffer<uint32_t> offsets(map.device(), total);
  dispatch(map.device(), [&](auto backend) {
    esdf_flag_band(backend, mutable_map.esdf().view(), block_slots.data(), blocks, side,
                   max_distance_m, flags.data(), stream);
  });
  algorithms::exclusive_scan(map.device(), stream, flags.data(), total, offsets.data());
  const int64_t count = static_cast<int64_t>(offsets.element(total - 1, stream)) +
                        static_cast<int64_t>(flags.element(total - 1, stream));
  Buffer<Vec3f> positions(map.device(), static_cast<size_t>(count));
  Buffer<float> distances(map.device(), static_cast<size_t>(count));
  dispatch(map.device(), [&](auto backend) {
    esdf_gather_band(backend, mutable_map.esdf().view(), block_indices.data(), block_slots.data(),
                     blocks, side, map.voxel_size_m(), flags.data(), offsets.data(),
                     positions.data(), distances.data(), stream);
  });
  const std::vector<Vec3f> host_positions = positions.to_host(stream);
  const std::vector<float> host_distances = distances.to_host(stream);
  std::vector<SlicePoint> voxels(static_cast<size_t>(count));
  for (int64_t i = 0; i < count; ++i) {
    voxels[i].position_m = host_positions[i];
    voxels[i].distance_m = host_distances[i];
  }
  return voxels;
}

}  // namespace covox::integrators
