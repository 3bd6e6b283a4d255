// map_depth_folder: maps a folder of depth images with their poses (7-Scenes, 3DMatch or Replica
// layout, io/rgbd_folder.h) into one TSDF with pipeline::Mapper, configured from a preset of
// config/ or a configuration file, then prints the ESDF at the first camera and writes the mesh.
//
//   map_depth_folder [FOLDER [PRESET|FILE.yaml [MESH.ply]]]
//   (defaults: the shared data's nvblox-testdata/3dmatch/seq-01, rgbd, map_depth_folder.ply)
#include <cstdio>
#include <string>

#include "covoxslam/core/device.h"
#include "covoxslam/core/error.h"
#include "covoxslam/io/data_directory.h"
#include "covoxslam/io/rgbd_folder.h"
#include "covoxslam/pipeline/mapper.h"

int main(int argc, char** argv) {
  using namespace covox;
  const std::string folder_path =
      argc > 1 ? argv[1] : io::data_directory() + "/nvblox-testdata/3dmatch/seq-01";
  const std::string preset_or_file = argc > 2 ? argv[2] : "rgbd";
  const std::string mesh_path = argc > 3 ? argv[3] : "map_depth_folder.ply";
  try {
    pipeline::MapperConfig config = pipeline::load_mapper_config({preset_or_file});
    config.device = select_device(DeviceRequest::kAuto);
    pipeline::Mapper mapper(config);

    const io::RgbdFolder folder = io::RgbdFolder::open(folder_path);
    for (size_t i = 0; i < folder.size(); ++i) mapper.integrate_depth(folder.read_frame(i));
    mapper.update_esdf();

    const Eigen::Vector3d camera = folder.read_frame(0).T_world_camera.translation();
    const integrators::EsdfSample at_camera =
        mapper.query_esdf({Vec3f(float(camera.x()), float(camera.y()), float(camera.z()))})[0];
    std::printf("%zu frames on %s: %lld blocks; ESDF at the first camera: %s%.2f m\n",
                folder.size(), to_string(mapper.device()),
                static_cast<long long>(mapper.map().block_count()),
                at_camera.valid ? "" : "(unobserved) ", at_camera.distance_m);

    mapper.save_mesh(mesh_path);
    std::printf("mesh: %s\n", mesh_path.c_str());
  } catch (const Error& error) {
    std::fprintf(stderr, "map_depth_folder: %s\n", error.what());
    return 1;
  }
  return 0;
}
