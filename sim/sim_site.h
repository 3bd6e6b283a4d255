#pragma once
// A procedural search-and-rescue training site in the spirit of ARCHE: uneven ground, buildings
// with rooms and doorways (one of them on the flight path, entered and left through doors), rubble
// piles, poles and trees. Everything except the passage building keeps clear of the flight path,
// so the simulated drone never flies through an obstacle. Deterministic from the seed.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "sim/sim_flight.h"
#include "sim/sim_world.h"

namespace covox {
namespace sim {

struct SiteConfig {
  int extra_buildings = 3;
  int rubble_piles = 6;
  int poles = 14;
  int trees = 14;
  double ground_amplitude_m = 0.5;
  double ground_cell_m = 2.0;
  double margin_m = 25.0;         // ground beyond the path's bounding box
  double path_clearance_m = 3.0;  // obstacles keep this far from the path (plus their own size)

  // The counts of buildings, rubble piles, poles and trees for a figure 8 of `path`'s extent:
  // those above are for the default flight's figure 8 (FlightConfig's lobe half length and lap),
  // and a larger one gets proportionally more (its extent's area over the default's), so a
  // larger site is as built up as the default one.
  SiteConfig scaled_to(const Figure8Path& path) const;
};

// Axis-aligned footprint of a building, for placement and for tests.
struct Footprint {
  Eigen::Vector2d low_m, high_m;
};

struct Site {
  World world;
  std::vector<Footprint> buildings;  // the passage building first
  Eigen::Vector2d low_m, high_m;     // extent of the ground
};

// Builds (and World::build()s) the site around `path`.
Site build_site(const SiteConfig& config, const Figure8Path& path, uint64_t seed);

}  // namespace sim
}  // namespace covox
