#pragma once
// MapIntegrators: the integration stage of a map, apart from any map. It holds the TSDF, ESDF and
// mesh integrators, their scratch memory (allocated at the first call, then reused) and the
// stream they run on, and applies them to the map each call names; every call returns when its
// work is done. A Mapper (pipeline/mapper.h) is one map with a stage of its own. SlamSystem keeps
// one stage per thread and lends it to each submap in turn (the frontend's integrates scans into
// the active submap, the backend's finishes the submaps it receives), so the scratch memory is
// per thread, not per submap. One thread at a time.
#include <map>

#include <Eigen/Geometry>

#include "covoxslam/core/stream.h"
#include "covoxslam/integrators/esdf_integrator.h"
#include "covoxslam/integrators/mesh_integrator.h"
#include "covoxslam/integrators/tsdf_integrator.h"
#include "covoxslam/map/mesh.h"
#include "covoxslam/map/tsdf_map.h"

namespace covox {
namespace pipeline {

class MapIntegrators {
 public:
  // Integrators of these configurations, running on `stream` (of the maps' device). Throws
  // covox::Error for an ESDF configuration its integrator refuses.
  MapIntegrators(const integrators::TsdfIntegratorConfig& tsdf,
                 const integrators::EsdfIntegratorConfig& esdf,
                 const integrators::MeshIntegratorConfig& mesh, Stream stream);

  const Stream& stream() const { return stream_; }

  // A cloud in device memory (of the map's device), taken at T_map_sensor.
  integrators::IntegrationStats integrate(map::TsdfMap& map,
                                          const integrators::PointCloudView& cloud,
                                          const Eigen::Isometry3d& T_map_sensor);
  // A depth image in device memory, taken at T_map_camera.
  integrators::IntegrationStats integrate_depth(map::TsdfMap& map,
                                                const integrators::DepthImageView& image,
                                                const Eigen::Isometry3d& T_map_camera);
  // The ESDF around the blocks whose TSDF changed since its last update.
  integrators::EsdfUpdateStats update_esdf(map::TsdfMap& map);
  // The ESDF of the whole map.
  integrators::EsdfUpdateStats update_esdf_all(map::TsdfMap& map);
  // The mesh of the whole map, vertices welded everywhere.
  map::Mesh extract_mesh(map::TsdfMap& map);

  // Incremental meshing keeps one mesh per block of the map it updates in the mesh integrator:
  // only a stage that serves a single map (a Mapper's) uses these two.
  // Re-meshes the blocks whose TSDF changed since the last update.
  integrators::MeshUpdateStats update_mesh(map::TsdfMap& map);
  // The meshes update_mesh() keeps, one per block.
  const std::map<Index3D, map::Mesh>& block_meshes();

 private:
  Stream stream_;
  integrators::TsdfIntegrator tsdf_;
  integrators::EsdfIntegrator esdf_;
  integrators::MeshIntegrator mesher_;
};

}  // namespace pipeline
}  // namespace covox
