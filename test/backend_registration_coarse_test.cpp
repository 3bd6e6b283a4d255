// Coarse-to-fine registration (RegistrationAlignerConfig::coarse_levels): the strided ESDF lookup
// against the ESDF itself, and the aligner's basin on a revisit-sized offset (2.5 m, 10 degrees)
// that the fine level alone does not recover.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "covoxslam/backend/registration.h"
#include "covoxslam/backend/internal/registration_ops.h"
#include "covoxslam/core/error.h"
#include "support/per_device_cache.h"
#include "support/registration_room.h"
#include "support/test_devices.h"

namespace covox {
namespace backend {
namespace {

using testing_support::kDegToRad;

// A 12 x 9 x 3 m hall (large enough for a 2.5 m offset to leave most points inside it) scanned
// from two sensor poses, 0.1 m voxels, ESDF up to 3 m (the coarse levels' reach).
// A type of its own: once_per_device caches one value per type.
struct HallPair : testing_support::ScannedSubmapPair {};

const HallPair& hall_pair(Device device) {
  return testing_support::once_per_device<HallPair>(device, [](Device d) {
    testing_support::AnalyticScene hall;
    hall.shape = testing_support::Shape::kBox;
    hall.center = Eigen::Vector3d(0.7, -0.4, 0.6);
    hall.half_extent = Eigen::Vector3d(6.0, 4.5, 1.5);
    return HallPair{testing_support::scan_submap_pair(
        d, hall, Pose4Dof{0.9, -0.6, 0.05, 7.0 * kDegToRad}, 0.1f, 3.0f)};
  });
}

double translation_error_m(const Pose4Dof& a, const Pose4Dof& b) {
  return std::sqrt(std::pow(a.x - b.x, 2) + std::pow(a.y - b.y, 2) + std::pow(a.z - b.z, 2));
}

class CoarseRegistrationTest : public testing_support::DeviceTest {};

// At stride s the lookup's corners are ESDF voxels s apart (band 0): half way between two coarse
// corners along x the sample is their mean and the x gradient their difference over s voxels.
TEST_P(CoarseRegistrationTest, StridedLookupSamplesTheEsdfEveryStrideVoxels) {
  const HallPair& pair = hall_pair(device());
  if (device() != Device::kCpu) GTEST_SKIP() << "host lookup of a host map";
  RegistrationResidualConfig config;
  config.distance = RegistrationDistance::kEsdf;
  const RegistrationDistanceLookup fine = make_registration_lookup(*pair.map_j, config);
  config.distance = RegistrationDistance::kTsdfNearSurface;
  config.coarse_stride_vox = 4;
  const RegistrationDistanceLookup coarse = make_registration_lookup(*pair.map_j, config);
  EXPECT_EQ(coarse.stride_vox, 4);
  EXPECT_EQ(coarse.tsdf_band_m, 0.0f) << "a coarse level reads the ESDF only";
  EXPECT_FALSE(registration_uses_tsdf_target(config));
  const double voxel = 0.1;
  int checked = 0;
  for (int k = -12; k <= 8; k += 4) {
    // Coarse corners at voxel indices (k, 8, 4) and (k + 4, 8, 4); the query half way between.
    const double qy = (8 + 0.5) * voxel, qz = (4 + 0.5) * voxel;
    double d0 = 0.0, d1 = 0.0, d = 0.0, g0[3], g1[3], g[3];
    if (!fine.sample((k + 0.5) * voxel, qy, qz, &d0, g0) ||
        !fine.sample((k + 4.5) * voxel, qy, qz, &d1, g1) ||
        !coarse.sample((k + 2.5) * voxel, qy, qz, &d, g)) {
      continue;
    }
    EXPECT_NEAR(d, 0.5 * (d0 + d1), 1e-5) << "between voxels x " << k << " and " << k + 4;
    EXPECT_NEAR(g[0], (d1 - d0) / (4 * voxel), 1e-4)
        << "between voxels x " << k << " and " << k + 4;
    ++checked;
  }
  EXPECT_GE(checked, 4);
  RegistrationResidualConfig bad;
  bad.coarse_stride_vox = 0;
  EXPECT_THROW(
      evaluate_registration_residuals(*pair.points_i, *pair.map_j, Pose4Dof(), Pose4Dof(), bad),
      Error);
}

// The property the coarse levels are for: started 2.5 m and 10 degrees off (a revisit after the
// drift of a lobe), the fine cost alone stops in a wrong minimum, while three coarse levels
// (strides 8, 4, 2 voxels) bring the symmetric aligner (the ARCHE preset's) into the fine basin.
// The one-way results are printed only: in this hall of two-fold symmetry the one-way coarse cost
// slid 7.5 m for the first offset (its points left the partner's field until the few left fit;
// the symmetric cost keeps both submaps' points and does not).
TEST_P(CoarseRegistrationTest, CoarseToFineRecoversARevisitSizedOffset) {
  const HallPair& pair = hall_pair(device());
  const Stream stream(device());
  const Pose4Dof truth = pair.true_T_Sj_Si;
  const SymmetricRegistrationPair two_way = pair.symmetric();
  const Pose4Dof offsets[] = {{2.0, 1.5, 0.0, 10.0 * kDegToRad},
                              {-1.5, -2.0, 0.1, -10.0 * kDegToRad}};
  for (const bool symmetric : {false, true}) {
    for (const Pose4Dof& offset : offsets) {
      const Pose4Dof initial{truth.x + offset.x, truth.y + offset.y, truth.z + offset.z,
                             truth.yaw + offset.yaw};
      double error_m[2] = {0.0, 0.0}, error_deg[2] = {0.0, 0.0};
      bool converged[2] = {false, false};
      for (const int levels : {0, 3}) {
        RegistrationAlignerConfig config;
        config.coarse_levels = levels;
        RegistrationResult result;
        const int at = levels == 0 ? 0 : 1;
        try {
          result = symmetric ? align_submaps_symmetric(two_way, initial, config, stream)
                             : align_submaps(*pair.points_i, *pair.map_j, initial, config, stream);
          converged[at] = result.converged;
        } catch (const Error&) {
          result.T_Sj_Si = initial;  // the fine aligner gave up: as far off as it started
        }
        error_m[at] = translation_error_m(result.T_Sj_Si, truth);
        error_deg[at] = std::abs(result.T_Sj_Si.yaw - truth.yaw) / kDegToRad;
      }
      std::printf(
          "[ registration ] %s %s, offset (%.1f, %.1f m, %.0f deg): fine only %.3f m %.2f deg, "
          "coarse-to-fine %.3f m %.2f deg\n",
          to_string(device()), symmetric ? "symmetric" : "one-way", offset.x, offset.y,
          offset.yaw / kDegToRad, error_m[0], error_deg[0], error_m[1], error_deg[1]);
      if (!symmetric) continue;
      EXPECT_TRUE(error_m[0] > 0.5 || error_deg[0] > 2.0)
          << "the fine level alone already recovers this offset";
      EXPECT_TRUE(converged[1]);
      EXPECT_LT(error_m[1], 0.05);
      EXPECT_LT(error_deg[1], 0.2);
    }
  }
}

// The coarse levels' cap and scaled tolerances end them once the pose is in the next level's
// basin: fewer LM steps than coarse levels run to the fine tolerances (the earlier behaviour),
// and the same alignment to within a centimetre and a tenth of a degree.
TEST_P(CoarseRegistrationTest, CappedCoarseLevelsTakeFewerStepsToTheSameAlignment) {
  const HallPair& pair = hall_pair(device());
  const Stream stream(device());
  const SymmetricRegistrationPair two_way = pair.symmetric();
  const Pose4Dof truth = pair.true_T_Sj_Si;
  const Pose4Dof initial{truth.x + 2.0, truth.y + 1.5, truth.z, truth.yaw + 10.0 * kDegToRad};
  RegistrationAlignerConfig capped;
  capped.coarse_levels = 3;
  RegistrationAlignerConfig uncapped = capped;
  uncapped.coarse_max_iterations = uncapped.max_iterations;
  uncapped.coarse_tolerance_scale = 1.0;
  const RegistrationResult a = align_submaps_symmetric(two_way, initial, capped, stream);
  const RegistrationResult b = align_submaps_symmetric(two_way, initial, uncapped, stream);
  std::printf("[ registration ] %s: %d LM steps capped, %d uncapped\n", to_string(device()),
              a.iterations, b.iterations);
  EXPECT_TRUE(a.converged);
  EXPECT_LT(a.iterations, b.iterations);
  EXPECT_LT(translation_error_m(a.T_Sj_Si, b.T_Sj_Si), 0.01);
  EXPECT_LT(std::abs(a.T_Sj_Si.yaw - b.T_Sj_Si.yaw) / kDegToRad, 0.1);
  EXPECT_LT(translation_error_m(a.T_Sj_Si, truth), 0.05);
}

TEST_P(CoarseRegistrationTest, BadLevelSettingsAreErrors) {
  const HallPair& pair = hall_pair(device());
  const Stream stream(device());
  RegistrationAlignerConfig levels;
  levels.coarse_levels = -1;
  RegistrationAlignerConfig cap;
  cap.coarse_max_iterations = 0;
  RegistrationAlignerConfig scale;
  scale.coarse_tolerance_scale = 0.5;
  for (const RegistrationAlignerConfig& config : {levels, cap, scale}) {
    EXPECT_THROW(align_submaps(*pair.points_i, *pair.map_j, pair.true_T_Sj_Si, config, stream),
                 Error);
  }
}

COVOX_INSTANTIATE_ON_ALL_DEVICES(CoarseRegistrationTest);

}  // namespace
}  // namespace backend
}  // namespace covox
