#pragma once
// Voxel types stored in block layers. Zero bytes are the "never observed" voxel, so freshly
// allocated blocks are cleared with a memset.
#include <cstdint>

#include "covoxslam/core/soa_container.h"

namespace covox::map {

// Truncated signed distance (metres, positive in front of the surface) and its fusion weight.
struct TsdfVoxel {
  float distance_m = 0.0f;
  float weight = 0.0f;
};

// Running average colour and its weight.
struct ColorVoxel {
  uint8_t r = 0;
  uint8_t g = 0;
  uint8_t b = 0;
  float weight = 0.0f;
};

// TSDF and colour in one voxel (16 bytes in AoS): the layout benchmark's "TSDF-like voxel" and
// what a single-layer colour map would store.
struct ColoredTsdfVoxel {
  float distance_m = 0.0f;
  float weight = 0.0f;
  uint8_t r = 0;
  uint8_t g = 0;
  uint8_t b = 0;
  float color_weight = 0.0f;
};

// Euclidean signed distance (metres) to the nearest surface site, positive in free space.
// `observed` is 0 where the TSDF never saw the voxel: its distance means nothing there.
struct EsdfVoxel {
  float distance_m = 0.0f;
  uint8_t observed = 0;
  uint8_t is_site = 0;
};

}  // namespace covox::map

// The field lists specialise core's VoxelFields, so they live in its namespace.
namespace covox {

template <>
struct VoxelFields<map::TsdfVoxel> {
  using type = FieldList<&map::TsdfVoxel::distance_m, &map::TsdfVoxel::weight>;
};

template <>
struct VoxelFields<map::ColorVoxel> {
  using type = FieldList<&map::ColorVoxel::r, &map::ColorVoxel::g, &map::ColorVoxel::b,
                         &map::ColorVoxel::weight>;
};

template <>
struct VoxelFields<map::ColoredTsdfVoxel> {
  using type = FieldList<&map::ColoredTsdfVoxel::distance_m, &map::ColoredTsdfVoxel::weight,
                         &map::ColoredTsdfVoxel::r, &map::ColoredTsdfVoxel::g,
                         &map::ColoredTsdfVoxel::b, &map::ColoredTsdfVoxel::color_weight>;
};

template <>
struct VoxelFields<map::EsdfVoxel> {
  using type =
      FieldList<&map::EsdfVoxel::distance_m, &map::EsdfVoxel::observed, &map::EsdfVoxel::is_site>;
};

}  // namespace covox
