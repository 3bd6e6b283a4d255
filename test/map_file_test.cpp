// Map files: save then load is bit-exact; truncated, corrupted and foreign files are rejected.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <unistd.h>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "covoxslam/core/error.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/io/map_file.h"
#include "covoxslam/io/submap_codec.h"
#include "support/analytic_tsdf.h"
#include "support/test_devices.h"

namespace covox {
namespace {

using testing_support::DeviceTest;

std::string temporary_path(const std::string& name) {
  return ::testing::TempDir() + "/covox_" + name + "_" + std::to_string(::getpid());
}

std::vector<unsigned char> read_bytes(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return std::vector<unsigned char>((std::istreambuf_iterator<char>(file)),
                                    std::istreambuf_iterator<char>());
}
void write_bytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  file.write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

bool same_blocks(const std::vector<map::HostBlock>& a, const std::vector<map::HostBlock>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (!(a[i].index == b[i].index)) return false;
    for (size_t k = 0; k < a[i].tsdf.size(); ++k) {
      if (std::memcmp(&a[i].tsdf[k].distance_m, &b[i].tsdf[k].distance_m, 4) ||
          std::memcmp(&a[i].tsdf[k].weight, &b[i].tsdf[k].weight, 4) ||
          a[i].color[k].r != b[i].color[k].r || a[i].color[k].g != b[i].color[k].g ||
          a[i].color[k].b != b[i].color[k].b ||
          std::memcmp(&a[i].color[k].weight, &b[i].color[k].weight, 4) ||
          std::memcmp(&a[i].esdf[k].distance_m, &b[i].esdf[k].distance_m, 4) ||
          a[i].esdf[k].observed != b[i].esdf[k].observed ||
          a[i].esdf[k].is_site != b[i].esdf[k].is_site) {
        return false;
      }
    }
  }
  return true;
}

class MapFileTest : public DeviceTest {
 protected:
  io::MapFileContents make_contents() {
    io::MapFileContents contents;
    contents.voxel_size_m = 0.1f;
    contents.voxels_per_side = 8;
    contents.has_esdf = true;
    for (int s = 0; s < 2; ++s) {
      map::TsdfMap map(device(), map::TsdfMapConfig{0.1f, 8, {}});
      const Eigen::Vector3d centre(0.3 * s, 0.1, -0.2);
      testing_support::fill_tsdf(
          map, Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1), 0.4f,
          [&](const Eigen::Vector3d& p) { return (p - centre).norm() - 0.6; });
      integrators::EsdfIntegrator(integrators::EsdfIntegratorConfig{})
          .update(map, Stream(device()));
      io::SubmapRecord record;
      record.id = 10 + s;
      record.T_world_submap.translation() = Eigen::Vector3d(1.5 * s, -2.0, 0.25);
      record.T_world_submap.linear() =
          Eigen::AngleAxisd(0.3 * s, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      record.blocks = map.snapshot();
      contents.submaps.push_back(std::move(record));
    }
    return contents;
  }
};

TEST_P(MapFileTest, SaveThenLoadKeepsTheQuantisedMapAndSavesTheSameBytes) {
  const io::MapFileContents saved = make_contents();
  const std::string path = temporary_path("roundtrip.cvxmap");
  io::save_map_file(path, saved);
  const io::MapFileContents loaded = io::load_map_file(path);
  ASSERT_EQ(loaded.submaps.size(), 2u);
  EXPECT_EQ(loaded.voxel_size_m, saved.voxel_size_m);
  EXPECT_EQ(loaded.voxels_per_side, saved.voxels_per_side);
  EXPECT_FALSE(loaded.has_esdf);  // recomputed by whoever builds the map
  EXPECT_GT(loaded.distance_scale_m, 0.0f);
  for (size_t s = 0; s < 2; ++s) {
    EXPECT_EQ(loaded.submaps[s].id, saved.submaps[s].id);
    EXPECT_EQ(loaded.submaps[s].T_world_submap.matrix(), saved.submaps[s].T_world_submap.matrix());
    // Exactly what the codec gives back for the saved blocks.
    const std::vector<map::HostBlock> expected = io::decode_submap(
        io::encode_submap(saved.submaps[s].blocks, 8, loaded.distance_scale_m), "expected");
    ASSERT_EQ(loaded.submaps[s].blocks.size(), expected.size());
    for (size_t b = 0; b < expected.size(); ++b) {
      EXPECT_TRUE(loaded.submaps[s].blocks[b].index == expected[b].index);
      EXPECT_EQ(0, std::memcmp(loaded.submaps[s].blocks[b].tsdf.data(), expected[b].tsdf.data(),
                               expected[b].tsdf.size() * sizeof(map::TsdfVoxel)));
    }
  }
  // save -> load -> save gives the same file, byte for byte.
  const std::string again = temporary_path("roundtrip_again.cvxmap");
  io::save_map_file(again, loaded);
  EXPECT_EQ(read_bytes(path), read_bytes(again));
  // Through the device maps: the blocks as loaded.
  const auto maps = io::make_maps(loaded, device());
  EXPECT_EQ(maps[1]->block_count(), static_cast<int64_t>(loaded.submaps[1].blocks.size()));
  std::remove(path.c_str());
  std::remove(again.c_str());
}

// Loading compact forms (what the node does, so a large map is never decoded whole) gives the
// bytes the file stores: they decode to the blocks a decoded load gives, and a version 1 file's
// blocks come encoded with its largest |distance|, decoding within the codec's bound.
TEST_P(MapFileTest, EncodedLoadGivesTheStoredCompactForms) {
  const io::MapFileContents saved = make_contents();
  const std::string path = temporary_path("encoded.cvxmap");
  io::save_map_file(path, saved);
  const io::MapFileContents decoded = io::load_map_file(path);
  const io::MapFileContents encoded = io::load_map_file(path, io::MapFileVoxels::kEncoded);
  ASSERT_EQ(encoded.submaps.size(), decoded.submaps.size());
  EXPECT_EQ(encoded.distance_scale_m, decoded.distance_scale_m);
  for (size_t s = 0; s < encoded.submaps.size(); ++s) {
    EXPECT_TRUE(encoded.submaps[s].blocks.empty());
    // The decoded load's blocks encode back to these bytes (the codec is idempotent).
    EXPECT_EQ(encoded.submaps[s].encoded,
              io::encode_submap(decoded.submaps[s].blocks, 8, decoded.distance_scale_m));
  }
  const std::string version1 = temporary_path("encoded_v1.cvxmap");
  io::save_map_file_version1(version1, saved);
  const io::MapFileContents from_v1 = io::load_map_file(version1, io::MapFileVoxels::kEncoded);
  ASSERT_EQ(from_v1.submaps.size(), saved.submaps.size());
  EXPECT_GT(from_v1.distance_scale_m, 0.0f);
  for (size_t s = 0; s < saved.submaps.size(); ++s) {
    const std::vector<map::HostBlock> back = io::decode_submap(from_v1.submaps[s].encoded, "v1");
    ASSERT_EQ(back.size(), saved.submaps[s].blocks.size());
    for (size_t b = 0; b < back.size(); ++b) {
      for (size_t v = 0; v < back[b].tsdf.size(); ++v) {
        ASSERT_NEAR(back[b].tsdf[v].distance_m, saved.submaps[s].blocks[b].tsdf[v].distance_m,
                    from_v1.distance_scale_m / 65534.0 + 1e-6);
      }
    }
  }
  std::remove(path.c_str());
  std::remove(version1.c_str());
}

TEST_P(MapFileTest, Version1FilesStillLoadBitExact) {
  const io::MapFileContents saved = make_contents();
  const std::string path = temporary_path("version1.cvxmap");
  io::save_map_file_version1(path, saved);
  const io::MapFileContents loaded = io::load_map_file(path);
  ASSERT_EQ(loaded.submaps.size(), 2u);
  EXPECT_TRUE(loaded.has_esdf);
  for (size_t s = 0; s < 2; ++s) {
    EXPECT_EQ(loaded.submaps[s].id, saved.submaps[s].id);
    EXPECT_TRUE(same_blocks(loaded.submaps[s].blocks, saved.submaps[s].blocks));
  }
  // And version 2 of it is smaller: no ESDF, quantised fields, no padding.
  const std::string version2 = temporary_path("version2.cvxmap");
  io::save_map_file(version2, loaded);
  const size_t bytes_v1 = read_bytes(path).size(), bytes_v2 = read_bytes(version2).size();
  std::cout << "map file: version 1 " << bytes_v1 << " bytes, version 2 " << bytes_v2 << "\n";
  EXPECT_LT(2 * bytes_v2, bytes_v1);
  std::remove(path.c_str());
  std::remove(version2.c_str());
}

TEST_P(MapFileTest, AFailedWriteLeavesTheOldFile) {
  const std::string path = temporary_path("kept.cvxmap");
  io::save_map_file(path, make_contents());
  const auto before = read_bytes(path);
  {
    io::MapFileWriter writer(path, 0.1f, 8, 0.4f);
    // Encoded with another distance scale: refused, and the writer is dropped uncommitted.
    EXPECT_THROW(writer.add_submap(1, Eigen::Isometry3d::Identity(),
                                   io::encode_submap(make_contents().submaps[0].blocks, 8, 0.5f)),
                 Error);
  }
  EXPECT_EQ(read_bytes(path), before);
  const std::string name = std::filesystem::path(path).filename().string();
  for (const auto& entry : std::filesystem::directory_iterator(::testing::TempDir())) {
    EXPECT_NE(entry.path().filename().string().rfind("." + name + ".", 0), 0u)
        << "the temporary file was left behind: " << entry.path();
  }
  std::remove(path.c_str());
}

// A file with a valid checksum whose submap pose is not a rotation (scaled, sheared, mirrored,
// NaN) is refused naming the submap; rounding-level noise is not.
TEST_P(MapFileTest, NonRigidSubmapPosesAreRefusedNamingTheSubmap) {
  const io::MapFileContents contents = make_contents();
  const std::string path = temporary_path("pose.cvxmap");
  const std::vector<uint8_t> encoded = io::encode_submap(contents.submaps[0].blocks, 8, 0.4f);
  auto save_with = [&](const Eigen::Matrix4d& pose) {
    io::MapFileWriter writer(path, 0.1f, 8, 0.4f);
    writer.add_submap(3, Eigen::Isometry3d::Identity(), encoded);
    Eigen::Isometry3d bad;
    bad.matrix() = pose;
    writer.add_submap(7, bad, encoded);
    writer.commit();
  };
  Eigen::Matrix4d scaled = Eigen::Matrix4d::Identity();
  scaled.topLeftCorner<3, 3>() *= 1.1;
  Eigen::Matrix4d sheared = Eigen::Matrix4d::Identity();
  sheared(0, 1) = 0.2;
  Eigen::Matrix4d mirrored = Eigen::Matrix4d::Identity();
  mirrored(2, 2) = -1.0;
  Eigen::Matrix4d not_a_number = Eigen::Matrix4d::Identity();
  not_a_number(1, 3) = std::nan("");
  Eigen::Matrix4d projective = Eigen::Matrix4d::Identity();
  projective(3, 0) = 0.5;
  for (const Eigen::Matrix4d& pose : {scaled, sheared, mirrored, not_a_number, projective}) {
    save_with(pose);
    try {
      io::load_map_file(path);
      ADD_FAILURE() << "accepted the pose\n" << pose;
    } catch (const Error& error) {
      EXPECT_NE(std::string(error.what()).find("submap 7's pose"), std::string::npos)
          << error.what();
      EXPECT_NE(std::string(error.what()).find(path), std::string::npos) << error.what();
    }
  }
  Eigen::Matrix4d rounded = Eigen::Matrix4d::Identity();
  rounded.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  rounded(0, 0) += 1e-12;
  save_with(rounded);
  const io::MapFileContents loaded = io::load_map_file(path, io::MapFileVoxels::kEncoded);
  ASSERT_EQ(loaded.submaps.size(), 2u);
  EXPECT_TRUE(loaded.submaps[1].T_world_submap.matrix().isApprox(rounded, 1e-15));
  std::remove(path.c_str());
}

TEST_P(MapFileTest, TruncatedCorruptedAndForeignFilesAreRejected) {
  const std::string path = temporary_path("damaged.cvxmap");
  io::save_map_file(path, make_contents());
  const auto good = read_bytes(path);

  auto expect_rejected = [&](const std::vector<unsigned char>& bytes, const char* what,
                             const char* message) {
    write_bytes(path, bytes);
    try {
      io::load_map_file(path);
      ADD_FAILURE() << what << " was accepted";
    } catch (const Error& error) {
      EXPECT_NE(std::string(error.what()).find(message), std::string::npos)
          << what << ": " << error.what();
    }
  };
  expect_rejected(std::vector<unsigned char>(good.begin(), good.begin() + good.size() / 2),
                  "truncated", "checksum");
  std::vector<unsigned char> flipped = good;
  flipped[good.size() / 3] ^= 0x10;
  expect_rejected(flipped, "corrupted", "checksum");
  expect_rejected(std::vector<unsigned char>(good.begin(), good.begin() + 10), "tiny", "truncated");
  const std::vector<unsigned char> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13};
  expect_rejected(png, "foreign", "not a covoxslam map");
  std::vector<unsigned char> future = good;
  future[8] = 99;  // version
  expect_rejected(future, "newer version", "version");
  // Each message says what was expected and what was found.
  const std::string missing = temporary_path("does_not_exist");
  expect_rejected(png, "foreign",
                  "starts with '\\x89PNG\\x0d\\x0a\\x1a\\x0a', expected 'COVOXMAP'");
  expect_rejected(std::vector<unsigned char>(good.begin(), good.begin() + 10), "tiny",
                  "10 bytes, shorter than the 12-byte header");
  future[8] = 7;
  expect_rejected(future, "newer version", "format version 7, this build reads versions 1 and 2");
  try {
    io::load_map_file(missing);
    ADD_FAILURE() << "a missing file was accepted";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find(missing + ": cannot open: No such file"),
              std::string::npos)
        << error.what();
  }
  try {
    io::load_map_file(::testing::TempDir());
    ADD_FAILURE() << "a folder was accepted";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("not a regular file"), std::string::npos)
        << error.what();
  }
  std::remove(path.c_str());
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(MapFileTest);

}  // namespace
}  // namespace covox
