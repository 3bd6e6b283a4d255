#pragma once
// A simulated mission's scans into a flight bag (sim_flight_bag.h) as a recording of the real
// sensors would hold them: for scan k, first the odometry samples up to the end of its sweep
// (SimulatedMission::odometry_stamps: the tf at the scan's stamp among them), then its cloud and
// truth fix, recorded when the sweep ends (the OS1 driver publishes a cloud once its last column
// has fired). A lookup of the odometry at any point time of any sweep, the last one's included,
// thus falls between tf samples already in the bag.
#include <cstddef>

#include "sim/sim_flight_bag.h"
#include "sim/sim_lidar.h"
#include "sim/sim_mission.h"

namespace covox {
namespace sim {

// Scan `k` of `mission` (its points: mission.scan(k)); scans must come in order, from k = 0.
void write_mission_scan(FlightBagWriter* writer, const SimulatedMission& mission, size_t k,
                        const SweepScan& scan);

}  // namespace sim
}  // namespace covox
