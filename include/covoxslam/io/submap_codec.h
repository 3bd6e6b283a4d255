#pragma once
// The compact form of one finished submap's voxels: what a map file stores per submap and what a
// submap held outside the device keeps. It holds the TSDF and colour layers in fewer bytes (the
// quantisation and the layout: kSubmapCodecVersion below); the ESDF is not stored (it is
// recomputed from the decoded TSDF, see EsdfIntegrator::update_all). Quantisation is idempotent:
// encode(decode(encode(m))) == encode(m) byte for byte, so a submap that went through the codec
// once can leave and come back any number of times unchanged.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace io {

// Quantisation (each step documented so its effect can be bounded):
//   - distance: int16 of clamp(distance / distance_scale_m, -1, 1) * 32767, rounded to nearest:
//     at most distance_scale_m / 65534 (half a step) plus the float rounding of the decoded value
//     (distance_scale_m * 2^-23) off for |distance| <= distance_scale_m (the TSDF's truncation
//     distance, so every stored distance lies in range);
//   - TSDF and colour weights: IEEE binary16 (half), rounded to nearest even: a relative error of
//     at most 2^-11 for weights in [2^-14, 65504], an absolute one of at most 2^-25 below that;
//     larger weights saturate at 65504;
//   - colour bytes: exact.
// A voxel whose quantised fields are all zero is the "never observed" voxel; a block of only such
// voxels is dropped. A block stores a bit mask of its observed voxels and their fields only; its
// colour only where some observed voxel has colour (the sensor gave colour there).
//
// Layout (little-endian): "CVXS", codec version (u32), voxels per side (u32), distance scale
// (f32), block count (u64); per block, in increasing index order: index (3 x i32), flags (u8,
// bit 0: colour present), the observed mask (voxels_per_block / 8 bytes, voxel k is bit k % 8 of
// byte k / 8, voxels in the block's linear order), then for the n observed voxels in order:
// n distances (i16), n weights (u16 half); with colour: n x (r, g, b) bytes, n colour weights
// (u16 half).
constexpr uint32_t kSubmapCodecVersion = 1;

// IEEE binary16 conversions (round to nearest even; finite values above 65504 saturate, NaN and
// infinities keep their class).
uint16_t float_to_half(float value);
float half_to_float(uint16_t half);

// Encodes `blocks` (as TsdfMap::snapshot() returns them: sorted by index, voxels_per_side^3 TSDF
// and colour voxels each; ESDF voxels are ignored). Throws covox::Error for a block of the wrong
// size, unsorted or repeated indices, or a scale that is not a positive finite number.
std::vector<uint8_t> encode_submap(const std::vector<map::HostBlock>& blocks, int voxels_per_side,
                                   float distance_scale_m);
// encode_submap() of a map's blocks.
std::vector<uint8_t> encode_submap(const map::TsdfMap& map, float distance_scale_m);

struct EncodedSubmapInfo {
  int voxels_per_side = 0;
  float distance_scale_m = 0.0f;
  uint64_t blocks = 0;
};
// Checks every length, flag and index order of encoded bytes without building anything; throws
// covox::Error saying what is wrong (prefixed with `what`).
EncodedSubmapInfo validate_encoded_submap(const uint8_t* data, size_t size, const char* what);
// The blocks, sorted by index, with empty ESDF vectors; validates as above.
std::vector<map::HostBlock> decode_submap(const uint8_t* data, size_t size, const char* what);
inline std::vector<map::HostBlock> decode_submap(const std::vector<uint8_t>& bytes,
                                                 const char* what) {
  return decode_submap(bytes.data(), bytes.size(), what);
}

// The blocks' voxels side by side (map::HostVoxels, empty ESDF), in stored order; validates as
// above.
EncodedSubmapInfo decode_submap_voxels(const uint8_t* data, size_t size, const char* what,
                                       map::HostVoxels* voxels);

// Rebuilds `map` (cleared first) from encoded bytes; throws covox::Error when the bytes do not
// decode or their voxels per side differ from the map's.
void load_encoded_submap(const std::vector<uint8_t>& bytes, map::TsdfMap* map,
                         const Stream& stream);

}  // namespace io
}  // namespace covox
