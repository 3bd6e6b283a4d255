#pragma once
// A simulated mission's scans into a flight bag (sim_flight_bag.h) as a recording of the real
// sensors would hold them: for scan k, first the odometry samples up to the end of its sweep
// (SimulatedMission::odometry_stamps: the tf at the scan's stamp among them), then its cloud and
// truth fix, recorded when the sweep ends (the OS1 driver publishes a cloud once its last column
// has fired). A lookup of the odometry at any point time of any sweep, the last one's included,
// thus falls between tf samples already in the bag.
#include <cstddef>

#include "covoxslam/io/rosbag_tf_buffer.h"
#include "sim/sim_flight_bag.h"
#include "sim/sim_lidar.h"
#include "sim/sim_mission.h"

namespace covox {
namespace sim {

// Scan `k` of `mission` (its points: mission.scan(k)); scans must come in order, from k = 0.
void write_mission_scan(FlightBagWriter* writer, const SimulatedMission& mission, size_t k,
                        const SweepScan& scan);

// The tf of scan `k`'s sweep as a reader of the mission's bag gets it: the static transforms and
// the odometry samples from the scan's stamp to the end of its sweep, each the message the writer
// records, serialised and parsed again, so that a lookup gives the bag's transform bit for bit.
// TfBuffer interpolates between the two samples around a stamp, so a lookup at the scan's stamp
// or at any time of its sweep gives here what it gives in the whole bag's tf.
io::rosbag::TfBuffer sweep_tf(const SimulatedMission& mission, size_t k,
                              const ArcheBagLayout& layout = ArcheBagLayout());

}  // namespace sim
}  // namespace covox
