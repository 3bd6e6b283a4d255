#pragma once
// Voxel types stored in block layers. Zero bytes are the "never observed" voxel, so freshly
// allocated blocks are cleared with a memset.
#include <cstdint>

#include "covoxslam/core/soa_container.h"

namespace covox {

// Truncated signed distance (metres, positive in front of the surface) and its fusion weight.
struct TsdfVoxel {
  float distance_m = 0.0f;
  float weight = 0.0f;
};
template <>
struct VoxelFields<TsdfVoxel> {
  using type = FieldList<&TsdfVoxel::distance_m, &TsdfVoxel::weight>;
};

// Running average colour and its weight.
struct ColorVoxel {
  uint8_t r = 0;
  uint8_t g = 0;
  uint8_t b = 0;
  float weight = 0.0f;
};
template <>
struct VoxelFields<ColorVoxel> {
  using type = FieldList<&ColorVoxel::r, &ColorVoxel::g, &ColorVoxel::b, &ColorVoxel::weight>;
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
template <>
struct VoxelFields<ColoredTsdfVoxel> {
  using type =
      FieldList<&ColoredTsdfVoxel::distance_m, &ColoredTsdfVoxel::weight, &ColoredTsdfVoxel::r,
                &ColoredTsdfVoxel::g, &ColoredTsdfVoxel::b, &ColoredTsdfVoxel::color_weight>;
};

// Euclidean signed distance (metres) to the nearest surface site, positive in free space.
// `observed` is 0 where the TSDF never saw the voxel: its distance means nothing there.
struct EsdfVoxel {
  float distance_m = 0.0f;
  uint8_t observed = 0;
  uint8_t is_site = 0;
};
template <>
struct VoxelFields<EsdfVoxel> {
  using type = FieldList<&EsdfVoxel::distance_m, &EsdfVoxel::observed, &EsdfVoxel::is_site>;
};

}  // namespace covox
