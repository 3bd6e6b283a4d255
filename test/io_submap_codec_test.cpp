// The compact submap codec: the quantisation error stays within its documented bound on a real
// integrated map, the codec is idempotent, never-observed blocks are dropped, and the ESDF
// recomputed from the decoded TSDF is what the pipeline computes from that TSDF.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <vector>

#include "covoxslam/core/buffer.h"
#include "covoxslam/core/error.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/io/submap_codec.h"
#include "pipeline_test_scene.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using pipeline::test_scene::circle_pose;
using testing_support::DeviceTest;

constexpr float kTruncationM = 0.6f;

class SubmapCodecTest : public DeviceTest {
 protected:
  // A few LiDAR scans of the yard, coloured by height, integrated into one 8-voxel-block map.
  void integrate_yard(map::TsdfMap* map) {
    const sim::World world = pipeline::test_scene::make_yard();
    const sim::LidarConfig lidar = pipeline::test_scene::small_lidar();
    integrators::TsdfIntegratorConfig config = pipeline::test_scene::yard_config().tsdf;
    config.truncation_distance_m = kTruncationM;
    integrators::TsdfIntegrator integrator(config);
    const Stream stream(device());
    Buffer<Vec3f> points(device());
    Buffer<Rgb8> colors(device());
    for (int k = 0; k < 4; ++k) {
      const Eigen::Isometry3d pose = circle_pose(1.5 * k);
      const std::vector<Vec3f> cloud = sim::simulate_scan(world, lidar, pose, 7 + k);
      std::vector<Rgb8> rgb;
      for (const Vec3f& p : cloud) {
        const uint8_t level = static_cast<uint8_t>(std::min(255.0f, std::abs(p.z) * 60.0f));
        rgb.push_back(Rgb8{level, static_cast<uint8_t>(255 - level), 40});
      }
      points.copy_from_host(cloud, stream);
      colors.copy_from_host(rgb, stream);
      integrators::PointCloudView view;
      view.points = points.data();
      view.colors = k % 2 == 0 ? colors.data() : nullptr;  // colour from half of the scans
      view.count = static_cast<int64_t>(cloud.size());
      integrator.integrate(*map, view, pose, stream);
      stream.synchronize();
    }
  }
};

double half_bound(float value) {
  // Round to nearest: half a unit in the last place of binary16.
  const double magnitude = std::abs(static_cast<double>(value));
  if (magnitude < std::ldexp(1.0, -14)) return std::ldexp(1.0, -25);
  return magnitude * std::ldexp(1.0, -11);
}

TEST(HalfFloat, RoundsToNearestAndRoundTripsEveryHalf) {
  for (uint32_t h = 0; h < 0x7c00u; ++h) {
    const float value = io::half_to_float(static_cast<uint16_t>(h));
    EXPECT_EQ(io::float_to_half(value), h) << h;
    EXPECT_EQ(io::float_to_half(-value), h | 0x8000u) << h;
  }
  EXPECT_EQ(io::half_to_float(io::float_to_half(1.0f)), 1.0f);
  EXPECT_EQ(io::half_to_float(io::float_to_half(10000.0f)), 10000.0f);
  EXPECT_EQ(io::half_to_float(io::float_to_half(1e9f)), 65504.0f);  // saturates
  // 1 + 2^-11 lies halfway between 1 and 1 + 2^-10: ties go to the even mantissa (1).
  EXPECT_EQ(io::half_to_float(io::float_to_half(1.0f + std::ldexp(1.0f, -11))), 1.0f);
  EXPECT_EQ(io::half_to_float(io::float_to_half(0.3f)), 0.300048828125f);
}

TEST_P(SubmapCodecTest, ErrorWithinTheBoundAndUnobservedBlocksDropped) {
  map::TsdfMap map(device(), map::TsdfMapConfig{0.2f, 8, {}});
  integrate_yard(&map);
  const std::vector<map::HostBlock> original = map.snapshot();
  const std::vector<uint8_t> bytes = io::encode_submap(map, kTruncationM);
  const std::vector<map::HostBlock> decoded = io::decode_submap(bytes, "test");

  std::map<Index3D, const map::HostBlock*> by_index;
  for (const map::HostBlock& block : decoded) by_index[block.index] = &block;
  // Half a quantisation step, plus the float rounding of the decoded value.
  const double distance_bound = kTruncationM / 65534.0 + kTruncationM * std::ldexp(1.0, -23);
  double max_distance_error = 0.0;
  int64_t dropped = 0, colored_voxels = 0;
  for (const map::HostBlock& block : original) {
    const auto it = by_index.find(block.index);
    if (it == by_index.end()) {
      ++dropped;
      for (size_t k = 0; k < block.tsdf.size(); ++k) {
        EXPECT_EQ(io::float_to_half(block.tsdf[k].weight), 0u);
        EXPECT_EQ(block.color[k].r | block.color[k].g | block.color[k].b, 0);
      }
      continue;
    }
    const map::HostBlock& back = *it->second;
    for (size_t k = 0; k < block.tsdf.size(); ++k) {
      const double error = std::abs(double(back.tsdf[k].distance_m) - block.tsdf[k].distance_m);
      max_distance_error = std::max(max_distance_error, error);
      EXPECT_LE(std::abs(double(back.tsdf[k].weight) - block.tsdf[k].weight),
                half_bound(block.tsdf[k].weight));
      EXPECT_LE(std::abs(double(back.color[k].weight) - block.color[k].weight),
                half_bound(block.color[k].weight));
      EXPECT_EQ(back.color[k].r, block.color[k].r);
      EXPECT_EQ(back.color[k].g, block.color[k].g);
      EXPECT_EQ(back.color[k].b, block.color[k].b);
      if (block.color[k].weight > 0.0f) ++colored_voxels;
    }
  }
  EXPECT_LE(max_distance_error, distance_bound);
  EXPECT_GT(colored_voxels, 0);
  const size_t full_bytes = original.size() * 512 * (8 + 7 + 6);
  std::cout << "blocks " << original.size() << " kept " << decoded.size() << " dropped " << dropped
            << "; bytes full " << full_bytes << " encoded " << bytes.size()
            << "; max distance error " << max_distance_error << " m (bound " << distance_bound
            << ")\n";
  EXPECT_EQ(decoded.size() + static_cast<size_t>(dropped), original.size());
  EXPECT_LT(bytes.size() * 4, full_bytes);
}

TEST_P(SubmapCodecTest, EncodingIsIdempotent) {
  map::TsdfMap map(device(), map::TsdfMapConfig{0.2f, 8, {}});
  integrate_yard(&map);
  const std::vector<uint8_t> once = io::encode_submap(map, kTruncationM);
  map::TsdfMap back(device(), map::TsdfMapConfig{0.2f, 8, {}});
  io::load_encoded_submap(once, &back, Stream(device()));
  const std::vector<uint8_t> twice = io::encode_submap(back, kTruncationM);
  EXPECT_EQ(once, twice);
  // Through the device map once more (a submap that left and came back twice).
  map::TsdfMap again(device(), map::TsdfMapConfig{0.2f, 8, {}});
  io::load_encoded_submap(twice, &again, Stream(device()));
  EXPECT_EQ(io::encode_submap(again, kTruncationM), once);
}

// A compacted submap's map is released: no blocks, pools or buckets left on its device beyond a
// two-bucket table (an emptied map keeps its buckets: 2^16 of them by default), the same
// configuration, and it takes blocks again.
TEST_P(SubmapCodecTest, AReleasedMapHoldsNextToNothingAndTakesBlocksAgain) {
  const map::TsdfMapConfig config{0.2f, 8, {}};
  map::TsdfMap map(device(), config);
  integrate_yard(&map);
  const std::vector<uint8_t> bytes = io::encode_submap(map, kTruncationM);
  const int64_t slots = map.pool_slots();
  ASSERT_GT(slots, 0);
  // SoA pools: 8 + 7 + 6 bytes a voxel; a bucket: an 8-byte key and a 4-byte slot.
  EXPECT_EQ(map.device_bytes(),
            slots * 512 * 21 + static_cast<int64_t>(map.blocks().bucket_count()) * 12);
  map.clear();
  EXPECT_GE(map.device_bytes(), int64_t{1} << 16) << "clear() keeps the buckets";
  map.release();
  EXPECT_EQ(map.block_count(), 0);
  EXPECT_EQ(map.device_bytes(), 2 * 12);
  EXPECT_EQ(map.config().voxels_per_side, 8);
  EXPECT_EQ(map.config().block_table.initial_bucket_count, config.block_table.initial_bucket_count);
  io::load_encoded_submap(bytes, &map, Stream(device()));
  EXPECT_EQ(io::encode_submap(map, kTruncationM), bytes);
}

// Decoding side by side (what a restore loads) gives the voxels of decoding block by block, in
// the same order, and a map loaded either way holds the same blocks; arrays of the wrong length
// are refused.
TEST_P(SubmapCodecTest, SideBySideDecodingMatchesBlockByBlock) {
  map::TsdfMap map(device(), map::TsdfMapConfig{0.2f, 8, {}});
  integrate_yard(&map);
  const std::vector<uint8_t> bytes = io::encode_submap(map, kTruncationM);
  const std::vector<map::HostBlock> blocks = io::decode_submap(bytes, "test");
  map::HostVoxels voxels;
  const io::EncodedSubmapInfo info =
      io::decode_submap_voxels(bytes.data(), bytes.size(), "test", &voxels);
  ASSERT_EQ(info.blocks, blocks.size());
  ASSERT_EQ(voxels.indices.size(), blocks.size());
  const size_t per_block = 8 * 8 * 8;
  ASSERT_EQ(voxels.tsdf.size(), blocks.size() * per_block);
  ASSERT_EQ(voxels.color.size(), blocks.size() * per_block);
  EXPECT_TRUE(voxels.esdf.empty());
  for (size_t b = 0; b < blocks.size(); ++b) {
    ASSERT_EQ(voxels.indices[b], blocks[b].index);
    for (size_t k = 0; k < per_block; ++k) {
      const map::TsdfVoxel& a = voxels.tsdf[b * per_block + k];
      const map::ColorVoxel& c = voxels.color[b * per_block + k];
      ASSERT_EQ(a.distance_m, blocks[b].tsdf[k].distance_m);
      ASSERT_EQ(a.weight, blocks[b].tsdf[k].weight);
      ASSERT_EQ(c.r, blocks[b].color[k].r);
      ASSERT_EQ(c.weight, blocks[b].color[k].weight);
    }
  }
  map::TsdfMap from_blocks(device(), map::TsdfMapConfig{0.2f, 8, {}});
  from_blocks.load_blocks(blocks, Stream(device()));
  map::TsdfMap from_bytes(device(), map::TsdfMapConfig{0.2f, 8, {}});
  io::load_encoded_submap(bytes, &from_bytes, Stream(device()));
  EXPECT_EQ(io::encode_submap(from_blocks, kTruncationM),
            io::encode_submap(from_bytes, kTruncationM));
  map::HostVoxels short_color = voxels;
  short_color.color.pop_back();
  map::TsdfMap refused(device(), map::TsdfMapConfig{0.2f, 8, {}});
  EXPECT_THROW(refused.load_voxels(short_color, Stream(device())), Error);
  EXPECT_EQ(refused.block_count(), 0);
}

// The blocks the codec drops hold no observed voxel, so the ESDF computed from the decoded map
// equals, voxel for voxel, the ESDF computed from the same quantised TSDF with those blocks still
// allocated (what a pipeline that kept them would compute).
TEST_P(SubmapCodecTest, EsdfFromDecodedTsdfMatchesTheFullMapsEsdf) {
  map::TsdfMap map(device(), map::TsdfMapConfig{0.2f, 8, {}});
  integrate_yard(&map);
  const std::vector<uint8_t> bytes = io::encode_submap(map, kTruncationM);
  const std::vector<map::HostBlock> decoded = io::decode_submap(bytes, "test");
  std::map<Index3D, const map::HostBlock*> by_index;
  for (const map::HostBlock& block : decoded) by_index[block.index] = &block;
  // The full block set, each voxel replaced by its quantised value (zero in dropped blocks).
  std::vector<map::HostBlock> full = map.snapshot();
  for (map::HostBlock& block : full) {
    block.esdf.clear();
    const auto it = by_index.find(block.index);
    for (size_t k = 0; k < block.tsdf.size(); ++k) {
      block.tsdf[k] = it == by_index.end() ? map::TsdfVoxel() : it->second->tsdf[k];
      block.color[k] = it == by_index.end() ? map::ColorVoxel() : it->second->color[k];
    }
  }
  const Stream stream(device());
  map::TsdfMap full_map(device(), map.config());
  full_map.load_blocks(full, stream);
  integrators::EsdfIntegrator(integrators::EsdfIntegratorConfig{}).update_all(full_map, stream);
  map::TsdfMap decoded_map(device(), map.config());
  io::load_encoded_submap(bytes, &decoded_map, stream);
  integrators::EsdfIntegrator(integrators::EsdfIntegratorConfig{}).update_all(decoded_map, stream);

  std::map<Index3D, map::HostBlock> full_esdf;
  for (map::HostBlock& block : full_map.snapshot()) full_esdf[block.index] = std::move(block);
  int64_t observed = 0;
  for (const map::HostBlock& block : decoded_map.snapshot()) {
    const map::HostBlock& reference = full_esdf.at(block.index);
    for (size_t k = 0; k < block.esdf.size(); ++k) {
      EXPECT_EQ(block.esdf[k].observed, reference.esdf[k].observed);
      EXPECT_EQ(block.esdf[k].is_site, reference.esdf[k].is_site);
      if (block.esdf[k].observed) {
        ++observed;
        EXPECT_EQ(block.esdf[k].distance_m, reference.esdf[k].distance_m);
      }
    }
  }
  EXPECT_GT(observed, 0);
  // The dropped blocks' ESDF voxels are unobserved in the full map too.
  for (const auto& [index, block] : full_esdf) {
    if (by_index.count(index)) continue;
    for (const map::EsdfVoxel& v : block.esdf) EXPECT_EQ(v.observed, 0);
  }
}

// Hand-made blocks with the voxels the quantisation treats specially: NaN and out-of-range
// distances, subnormal, saturating and zero weights, colour without distance, an all-unobserved
// block, colour in some blocks only.
std::vector<map::HostBlock> awkward_blocks(int voxels_per_side) {
  const size_t per_block = static_cast<size_t>(voxels_per_side) * voxels_per_side * voxels_per_side;
  std::vector<map::HostBlock> blocks;
  for (int b = 0; b < 5; ++b) {
    map::HostBlock block;
    block.index = Index3D(b - 2, b % 2, -b);
    block.tsdf.assign(per_block, map::TsdfVoxel());
    block.color.assign(per_block, map::ColorVoxel());
    if (b == 3) {  // never observed: dropped
      blocks.push_back(block);
      continue;
    }
    for (size_t k = 0; k < per_block; k += 1 + (k * 7 + b) % 5) {
      const float u = static_cast<float>((k * 2654435761u + b) % 10007) / 10007.0f;
      map::TsdfVoxel& t = block.tsdf[k];
      t.distance_m = (u - 0.5f) * 3.0f;  // beyond the 0.6 m scale at both ends
      t.weight = u < 0.1f ? std::ldexp(u, -20) : (u > 0.95f ? 1e6f : u * 200.0f);
      if (k % 97 == 5) t.distance_m = std::nanf("");
      if (k % 89 == 3) t.weight = 0.0f;
      if (b % 2 == 0) {
        map::ColorVoxel& c = block.color[k];
        c.r = static_cast<uint8_t>(k % 256);
        c.g = static_cast<uint8_t>((k / 3) % 256);
        c.b = static_cast<uint8_t>(b * 40);
        c.weight = u * 50.0f;
      }
      if (k % 61 == 7) {  // colour only
        t = map::TsdfVoxel();
        block.color[k].r = 9;
      }
    }
    blocks.push_back(block);
  }
  std::sort(blocks.begin(), blocks.end(),
            [](const map::HostBlock& a, const map::HostBlock& b) { return a.index < b.index; });
  return blocks;
}

// The map's own device encodes and decodes (what compaction and restores do): the bytes equal
// the host encoder's of the map's snapshot, and a decoded map holds the host decoder's voxels bit
// for bit, with a zero ESDF, on the yard and on the awkward blocks, 8 and 16 voxels a side.
TEST_P(SubmapCodecTest, TheMapsDeviceEncodesAndDecodesAsTheHostCodec) {
  const Stream stream(device());
  for (const int side : {8, 16}) {
    for (const bool yard : {true, false}) {
      map::TsdfMap map(device(), map::TsdfMapConfig{0.2f, side, {}});
      if (yard) {
        integrate_yard(&map);
      } else {
        map.load_blocks(awkward_blocks(side), stream);
      }
      const std::vector<map::HostBlock> snapshot = map.snapshot();
      const std::vector<uint8_t> bytes = io::encode_submap(map, kTruncationM);
      ASSERT_EQ(bytes, io::encode_submap(snapshot, side, kTruncationM))
          << side << " voxels a side, " << (yard ? "yard" : "awkward blocks");
      const std::vector<map::HostBlock> reference = io::decode_submap(bytes, "test");
      if (!yard) {
        ASSERT_EQ(reference.size() + 1, snapshot.size()) << "the unobserved block";
      }
      map::TsdfMap decoded(device(), map::TsdfMapConfig{0.2f, side, {}});
      io::load_encoded_submap(bytes, &decoded, stream);
      const std::vector<map::HostBlock> back = decoded.snapshot();
      ASSERT_EQ(back.size(), reference.size());
      for (size_t b = 0; b < back.size(); ++b) {
        ASSERT_EQ(back[b].index, reference[b].index);
        for (size_t k = 0; k < back[b].tsdf.size(); ++k) {
          const auto bits = [](float value) {
            uint32_t out;
            std::memcpy(&out, &value, sizeof(out));
            return out;
          };
          ASSERT_EQ(bits(back[b].tsdf[k].distance_m), bits(reference[b].tsdf[k].distance_m));
          ASSERT_EQ(bits(back[b].tsdf[k].weight), bits(reference[b].tsdf[k].weight));
          ASSERT_EQ(back[b].color[k].r, reference[b].color[k].r);
          ASSERT_EQ(back[b].color[k].g, reference[b].color[k].g);
          ASSERT_EQ(back[b].color[k].b, reference[b].color[k].b);
          ASSERT_EQ(bits(back[b].color[k].weight), bits(reference[b].color[k].weight));
          ASSERT_EQ(back[b].esdf[k].observed, 0);
          ASSERT_EQ(back[b].esdf[k].distance_m, 0.0f);
        }
      }
    }
  }
}

TEST_P(SubmapCodecTest, DamagedBytesAreRejected) {
  map::TsdfMap map(device(), map::TsdfMapConfig{0.2f, 8, {}});
  integrate_yard(&map);
  const std::vector<uint8_t> good = io::encode_submap(map, kTruncationM);
  EXPECT_NO_THROW(io::validate_encoded_submap(good.data(), good.size(), "test"));
  EXPECT_THROW(io::decode_submap(good.data(), good.size() - 1, "test"), Error);
  EXPECT_THROW(io::decode_submap(good.data(), 10, "test"), Error);
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_THROW(io::decode_submap(longer, "test"), Error);
  std::vector<uint8_t> version = good;
  version[4] = 7;
  EXPECT_THROW(io::decode_submap(version, "test"), Error);
  std::vector<uint8_t> count = good;
  count[16] = 0xff;  // the block count's low byte
  EXPECT_THROW(io::decode_submap(count, "test"), Error);
  map::TsdfMap other(device(), map::TsdfMapConfig{0.2f, 16, {}});
  EXPECT_THROW(io::load_encoded_submap(good, &other, Stream(device())), Error);
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(SubmapCodecTest);

}  // namespace
}  // namespace covox
