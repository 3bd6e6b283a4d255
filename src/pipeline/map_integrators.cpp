#include "covoxslam/pipeline/map_integrators.h"

#include <utility>

namespace covox {
namespace pipeline {

namespace {
// `result` once the work queued on `stream` so far is done: every call of a stage returns when
// its work is done, so the caller may read the map and reuse its inputs at once.
template <class Result>
Result when_done(const Stream& stream, Result result) {
  stream.synchronize();
  return result;
}
}  // namespace

MapIntegrators::MapIntegrators(const integrators::TsdfIntegratorConfig& tsdf,
                               const integrators::EsdfIntegratorConfig& esdf,
                               const integrators::MeshIntegratorConfig& mesh, Stream stream)
    : stream_(std::move(stream)), tsdf_(tsdf), esdf_(esdf), mesher_(mesh) {}

integrators::IntegrationStats MapIntegrators::integrate(map::TsdfMap& map,
                                                        const integrators::PointCloudView& cloud,
                                                        const Eigen::Isometry3d& T_map_sensor) {
  return when_done(stream_, tsdf_.integrate(map, cloud, T_map_sensor, stream_));
}

integrators::IntegrationStats MapIntegrators::integrate_depth(
    map::TsdfMap& map, const integrators::DepthImageView& image,
    const Eigen::Isometry3d& T_map_camera) {
  return when_done(stream_, tsdf_.integrate_depth(map, image, T_map_camera, stream_));
}

integrators::EsdfUpdateStats MapIntegrators::update_esdf(map::TsdfMap& map) {
  return when_done(stream_, esdf_.update(map, stream_));
}

integrators::EsdfUpdateStats MapIntegrators::update_esdf_all(map::TsdfMap& map) {
  return when_done(stream_, esdf_.update_all(map, stream_));
}

map::Mesh MapIntegrators::extract_mesh(map::TsdfMap& map) {
  return when_done(stream_, mesher_.extract_all(map, stream_));
}

integrators::MeshUpdateStats MapIntegrators::update_mesh(map::TsdfMap& map) {
  return when_done(stream_, mesher_.update(map, stream_));
}

const std::map<Index3D, map::Mesh>& MapIntegrators::block_meshes() {
  return mesher_.block_meshes(stream_);
}

}  // namespace pipeline
}  // namespace covox
