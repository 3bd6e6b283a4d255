#include "sim/sim_mission_bag.h"

namespace covox {
namespace sim {

void write_mission_scan(FlightBagWriter* writer, const SimulatedMission& mission, size_t k,
                        const SweepScan& scan) {
  for (const double stamp_s : mission.odometry_stamps(k))
    writer->write_odometry(stamp_s, mission.odometry_at(stamp_s));
  const double stamp_s = mission.truth().at(k).stamp_s;
  writer->write_cloud(stamp_s, stamp_s + mission.sweep_period_s(), mission.truth()[k].pose,
                      scan.points_sensor_m, scan.times_ns, {});
}

}  // namespace sim
}  // namespace covox
