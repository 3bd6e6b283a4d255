#include "sim/sim_mission_bag.h"

#include <vector>

namespace covox {
namespace sim {

namespace rb = io::rosbag;

namespace {

// Every transform of `message` into `tf` as the bag reader adds them: through the bytes.
void add_as_read(const rb::TfMessage& message, bool is_static, rb::TfBuffer* tf) {
  const std::vector<uint8_t> bytes = rb::serialize(message);
  const rb::TfMessage read = rb::parse_tf_message(bytes.data(), bytes.size(), "simulated tf");
  for (const rb::TransformStamped& transform : read.transforms) tf->add(transform, is_static);
}

}  // namespace

void write_mission_scan(FlightBagWriter* writer, const SimulatedMission& mission, size_t k,
                        const SweepScan& scan) {
  for (const double stamp_s : mission.odometry_stamps(k))
    writer->write_odometry(stamp_s, mission.odometry_at(stamp_s));
  const double stamp_s = mission.truth().at(k).stamp_s;
  writer->write_cloud(stamp_s, stamp_s + mission.sweep_period_s(), mission.truth()[k].pose,
                      scan.points_sensor_m, scan.times_ns, {});
}

rb::TfBuffer sweep_tf(const SimulatedMission& mission, size_t k, const ArcheBagLayout& layout) {
  const double stamp_s = mission.truth().at(k).stamp_s;
  rb::TfBuffer tf;
  add_as_read(static_tf_message(layout, rb::RosTime::from_seconds(stamp_s)), true, &tf);
  // The sample at the scan's stamp is the last of scan k - 1's (odometry_stamps) for k > 0.
  std::vector<double> stamps = mission.odometry_stamps(k);
  if (stamps.front() != stamp_s) stamps.insert(stamps.begin(), stamp_s);
  for (const double sample_s : stamps)
    add_as_read(odometry_tf_message(layout, sample_s, mission.odometry_at(sample_s), 0), false,
                &tf);
  return tf;
}

}  // namespace sim
}  // namespace covox
