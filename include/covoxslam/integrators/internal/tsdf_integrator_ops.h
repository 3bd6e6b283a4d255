#pragma once
// Backend-templated steps of TsdfIntegrator (defined in tsdf_integrator_impl.h, instantiated per
// backend). Scratch buffers are passed in so steady-state frames allocate nothing.
#include <cstdint>

#include <Eigen/Geometry>

#include "covoxslam/integrators/internal/tsdf_frame_strategy.h"
#include "covoxslam/integrators/internal/tsdf_scratch.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/integrators/internal/tsdf_kernels.h"

namespace covox::integrators {

template <class Backend>
IntegrationStats tsdf_integrate_points(Backend backend, const TsdfIntegratorConfig& config,
                                       const tsdf::FrameStrategy& strategy, map::TsdfMap& map,
                                       const PointCloudView& cloud,
                                       const Eigen::Isometry3d& T_map_sensor,
                                       TsdfScratchBuffers& scratch, const Stream& stream);

// Integrates a depth image's points (tsdf::DepthImagePoints, in tile order). The merged method
// reads the image in place: its first kernel unprojects each pixel as it bundles it and writes
// the points for the kernels after it (one kernel and one pass over the points fewer per frame
// than unprojecting first); the simple method has the image unprojected first.
template <class Backend>
IntegrationStats tsdf_integrate_depth_image(Backend backend, const TsdfIntegratorConfig& config,
                                            const tsdf::FrameStrategy& strategy, map::TsdfMap& map,
                                            const tsdf::DepthImagePoints& image,
                                            const Eigen::Isometry3d& T_map_camera,
                                            TsdfScratchBuffers& scratch, const Stream& stream);

// Writes width*height points (invalid pixels become (0,0,0), which integration drops as zero
// points) and colours into scratch.input, in tile order (tsdf::pixel_tile_order,
// tsdf_kernels.h).
template <class Backend>
void tsdf_unproject_depth(Backend backend, const tsdf::DepthImagePoints& image,
                          TsdfScratchBuffers& scratch, const Stream& stream);

}  // namespace covox::integrators
