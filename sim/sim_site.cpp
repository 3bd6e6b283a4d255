#include "sim/sim_site.h"

#include <algorithm>
#include <cmath>

#include "covoxslam/core/error.h"
#include "sim/sim_random.h"

namespace covox {
namespace sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kWallThickness_m = 0.25;
constexpr double kDoorHeight_m = 2.3;

const SurfaceColour kGround{125, 105, 75};
const SurfaceColour kWall{205, 200, 190};
const SurfaceColour kRoof{150, 65, 50};
const SurfaceColour kRubble{135, 135, 130};
const SurfaceColour kPole{80, 80, 95};
const SurfaceColour kTrunk{100, 70, 40};
const SurfaceColour kCrown{60, 140, 60};
const SurfaceColour kFurniture{165, 125, 85};

struct Door {
  double centre_m;  // along the wall, from its start
  double width_m;
};

double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

// Distance from a point to a footprint (0 inside).
double distance_to(const Footprint& footprint, const Eigen::Vector2d& p) {
  const Eigen::Vector2d outside =
      (footprint.low_m - p).cwiseMax(p - footprint.high_m).cwiseMax(0.0);
  return outside.norm();
}

Footprint grown(const Footprint& footprint, double margin_m) {
  return Footprint{footprint.low_m - Eigen::Vector2d::Constant(margin_m),
                   footprint.high_m + Eigen::Vector2d::Constant(margin_m)};
}

bool overlaps(const Footprint& a, const Footprint& b) {
  return (a.low_m.array() < b.high_m.array()).all() && (b.low_m.array() < a.high_m.array()).all();
}

// A straight wall from `start` to `end` (horizontal, on the ground), with doorways cut out: solid
// pieces between the doors, and lintels above them.
void add_wall(World* world, const Eigen::Vector2d& start, const Eigen::Vector2d& end,
              double height_m, std::vector<Door> doors) {
  const Eigen::Vector2d along = end - start;
  const double length = along.norm();
  const Eigen::Vector2d unit = along / length;
  Box piece;
  piece.rotation = Eigen::AngleAxisd(std::atan2(unit.y(), unit.x()), Eigen::Vector3d::UnitZ())
                       .toRotationMatrix();
  piece.colour = kWall;
  const auto add_piece = [&](double from_m, double to_m, double z_low, double z_high) {
    if (to_m - from_m < 1e-3 || z_high - z_low < 1e-3) return;
    const Eigen::Vector2d middle = start + unit * (0.5 * (from_m + to_m));
    piece.centre_m = Eigen::Vector3d(middle.x(), middle.y(), 0.5 * (z_low + z_high));
    piece.half_extent_m =
        Eigen::Vector3d(0.5 * (to_m - from_m), 0.5 * kWallThickness_m, 0.5 * (z_high - z_low));
    world->add(piece);
  };
  std::sort(doors.begin(), doors.end(),
            [](const Door& a, const Door& b) { return a.centre_m < b.centre_m; });
  double solid_from = 0.0;
  for (const Door& door : doors) {
    const double door_from = std::clamp(door.centre_m - 0.5 * door.width_m, 0.0, length);
    const double door_to = std::clamp(door.centre_m + 0.5 * door.width_m, 0.0, length);
    add_piece(solid_from, door_from, 0.0, height_m);
    add_piece(door_from, door_to, kDoorHeight_m, height_m);
    solid_from = door_to;
  }
  add_piece(solid_from, length, 0.0, height_m);
}

void add_roof(World* world, const Footprint& footprint, double height_m) {
  Box roof;
  const Eigen::Vector2d centre = 0.5 * (footprint.low_m + footprint.high_m);
  const Eigen::Vector2d half = 0.5 * (footprint.high_m - footprint.low_m);
  roof.centre_m = Eigen::Vector3d(centre.x(), centre.y(), height_m + 0.125);
  roof.half_extent_m = Eigen::Vector3d(half.x(), half.y(), 0.125);
  roof.colour = kRoof;
  world->add(roof);
}

void add_furniture(World* world, const Eigen::Vector2d& centre, const Eigen::Vector3d& size_m,
                   double yaw_rad) {
  Box box;
  box.centre_m = Eigen::Vector3d(centre.x(), centre.y(), 0.5 * size_m.z());
  box.half_extent_m = 0.5 * size_m;
  box.rotation = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  box.colour = kFurniture;
  world->add(box);
}

// The building the flight passes through: a corridor along y that the path follows, entered and
// left through doors where the path crosses the end walls, with two rooms on each side.
Footprint add_passage_building(World* world, const Figure8Path& path) {
  const double half_depth = 5.0, half_width = 7.0, height = 3.2;
  const double centre_x = path.passage_x_at_m(0.0);
  const double door_x = path.passage_x_at_m(-half_depth);  // symmetric: the same at +half_depth
  const double corridor_x = 0.5 * (centre_x + door_x);
  const double corridor_half = 2.0;
  const Footprint footprint{Eigen::Vector2d(centre_x - half_width, -half_depth),
                            Eigen::Vector2d(centre_x + half_width, half_depth)};
  const double x0 = footprint.low_m.x(), x1 = footprint.high_m.x();
  const double west = corridor_x - corridor_half, east = corridor_x + corridor_half;
  add_wall(world, {x0, -half_depth}, {x1, -half_depth}, height, {{door_x - x0, 1.8}});
  add_wall(world, {x0, half_depth}, {x1, half_depth}, height, {{door_x - x0, 1.8}});
  add_wall(world, {x0, -half_depth}, {x0, half_depth}, height, {{7.0, 1.0}});
  add_wall(world, {x1, -half_depth}, {x1, half_depth}, height, {{3.0, 1.0}});
  add_wall(world, {west, -half_depth}, {west, half_depth}, height, {{2.5, 1.0}, {7.5, 1.0}});
  add_wall(world, {east, -half_depth}, {east, half_depth}, height, {{2.5, 1.0}, {7.5, 1.0}});
  add_wall(world, {x0, 0.0}, {west, 0.0}, height, {});
  add_wall(world, {east, 0.0}, {x1, 0.0}, height, {});
  add_roof(world, footprint, height);
  add_furniture(world, {0.5 * (x0 + west), -2.5}, {1.2, 0.8, 0.75}, 0.3);
  add_furniture(world, {x0 + 0.5, 2.5}, {0.4, 1.6, 1.8}, 0.0);
  add_furniture(world, {0.5 * (east + x1), 2.5}, {1.4, 0.8, 0.75}, -0.2);
  add_furniture(world, {x1 - 0.5, -2.5}, {0.4, 1.6, 1.8}, 0.0);
  return footprint;
}

// An off-path building: outer doors on two walls, a partition with a door, a table.
void add_building(World* world, const Footprint& footprint, double height_m, Random* random) {
  const Eigen::Vector2d low = footprint.low_m, high = footprint.high_m;
  const Eigen::Vector2d size = high - low;
  const int first_door_wall = static_cast<int>(random->uniform() * 4.0);
  const Eigen::Vector2d corners[4] = {low, {high.x(), low.y()}, high, {low.x(), high.y()}};
  for (int wall = 0; wall < 4; ++wall) {
    const Eigen::Vector2d& a = corners[wall];
    const Eigen::Vector2d& b = corners[(wall + 1) % 4];
    const double length = (b - a).norm();
    std::vector<Door> doors;
    if (wall == first_door_wall || wall == (first_door_wall + 2) % 4) {
      doors.push_back({random->uniform(1.5, length - 1.5), random->uniform(1.0, 2.0)});
    }
    add_wall(world, a, b, height_m, doors);
  }
  // Partition across the longer side, with a door, making two rooms.
  if (size.x() >= size.y()) {
    const double x = low.x() + size.x() * random->uniform(0.35, 0.65);
    add_wall(world, {x, low.y()}, {x, high.y()}, height_m,
             {{random->uniform(1.0, size.y() - 1.0), 0.9}});
  } else {
    const double y = low.y() + size.y() * random->uniform(0.35, 0.65);
    add_wall(world, {low.x(), y}, {high.x(), y}, height_m,
             {{random->uniform(1.0, size.x() - 1.0), 0.9}});
  }
  add_roof(world, footprint, height_m);
  const Eigen::Vector2d table = low + Eigen::Vector2d(random->uniform(1.5, size.x() - 1.5),
                                                      random->uniform(1.5, size.y() - 1.5));
  add_furniture(world, table, {1.2, 0.8, 0.75}, random->uniform(0.0, kPi));
}

Eigen::Matrix3d random_rotation(Random* random) {
  Eigen::Quaterniond q(random->normal(), random->normal(), random->normal(), random->normal());
  q.normalize();
  return q.toRotationMatrix();
}

class Ground {
 public:
  Ground(const SiteConfig& config, const Eigen::Vector2d& low, const Eigen::Vector2d& high,
         const std::vector<Footprint>& buildings, Random* random)
      : low_(low), cell_(config.ground_cell_m) {
    columns_ = static_cast<int>(std::ceil((high.x() - low.x()) / cell_)) + 1;
    rows_ = static_cast<int>(std::ceil((high.y() - low.y()) / cell_)) + 1;
    // A few long waves and one short one, random in direction and phase.
    struct Wave {
      double kx, ky, phase, amplitude;
    };
    std::vector<Wave> waves;
    for (int i = 0; i < 4; ++i) {
      const double wavelength = i < 3 ? random->uniform(15.0, 40.0) : random->uniform(4.0, 7.0);
      const double angle = random->uniform(0.0, 2.0 * kPi);
      const double k = 2.0 * kPi / wavelength;
      waves.push_back({k * std::cos(angle), k * std::sin(angle), random->uniform(0.0, 2.0 * kPi),
                       i < 3 ? 0.3 : 0.1});
    }
    heights_.resize(static_cast<size_t>(columns_) * rows_);
    for (int j = 0; j < rows_; ++j) {
      for (int i = 0; i < columns_; ++i) {
        const Eigen::Vector2d p = vertex_xy(i, j);
        double h = 0.0;
        for (const Wave& wave : waves)
          h += wave.amplitude * std::sin(wave.kx * p.x() + wave.ky * p.y() + wave.phase);
        // Flat at and around buildings so that their floors meet the ground.
        double nearest = 1e9;
        for (const Footprint& building : buildings)
          nearest = std::min(nearest, distance_to(grown(building, 1.0), p));
        // The wave amplitudes add up to 1, so the ground stays within +-ground_amplitude_m.
        heights_[j * columns_ + i] = config.ground_amplitude_m * h * smoothstep(nearest / 6.0);
      }
    }
  }

  Eigen::Vector2d vertex_xy(int i, int j) const {
    return low_ + Eigen::Vector2d(i * cell_, j * cell_);
  }
  Eigen::Vector3d vertex(int i, int j) const {
    const Eigen::Vector2d p = vertex_xy(i, j);
    return Eigen::Vector3d(p.x(), p.y(), heights_[j * columns_ + i]);
  }
  // Lowest ground height of the cell holding p: where to sink object bases so they never float.
  double lowest_near(const Eigen::Vector2d& p) const {
    const int i = std::clamp(static_cast<int>((p.x() - low_.x()) / cell_), 0, columns_ - 2);
    const int j = std::clamp(static_cast<int>((p.y() - low_.y()) / cell_), 0, rows_ - 2);
    return std::min(
        {vertex(i, j).z(), vertex(i + 1, j).z(), vertex(i, j + 1).z(), vertex(i + 1, j + 1).z()});
  }
  void add_to(World* world) const {
    for (int j = 0; j + 1 < rows_; ++j) {
      for (int i = 0; i + 1 < columns_; ++i) {
        // Counter-clockwise seen from above: normals point up.
        world->add(Triangle{vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1), kGround});
        world->add(Triangle{vertex(i, j), vertex(i + 1, j + 1), vertex(i, j + 1), kGround});
      }
    }
  }

 private:
  Eigen::Vector2d low_;
  double cell_;
  int columns_ = 0, rows_ = 0;
  std::vector<double> heights_;
};

// A rubble pile of radius_m around spot: 10-16 blocks and slabs, higher in the middle.
void add_rubble_pile(const Eigen::Vector2d& spot, double radius_m, const Ground& ground,
                     Random* random, World* world) {
  const int pieces = 10 + static_cast<int>(random->uniform() * 7.0);
  for (int k = 0; k < pieces; ++k) {
    const double r = radius_m * std::sqrt(random->uniform());
    const double angle = random->uniform(0.0, 2.0 * kPi);
    const Eigen::Vector2d xy = spot + r * Eigen::Vector2d(std::cos(angle), std::sin(angle));
    Box piece;
    const bool slab = random->uniform() < 0.3;  // broken concrete slabs among the blocks
    piece.half_extent_m =
        slab ? Eigen::Vector3d(random->uniform(0.6, 1.1), random->uniform(0.4, 0.8), 0.08)
             : Eigen::Vector3d(random->uniform(0.15, 0.6), random->uniform(0.15, 0.6),
                               random->uniform(0.15, 0.5));
    piece.rotation = random_rotation(random);
    // Higher in the middle of the pile.
    piece.centre_m = Eigen::Vector3d(
        xy.x(), xy.y(), ground.lowest_near(xy) + random->uniform(0.0, 1.0) * (1.0 - r / radius_m));
    piece.colour = kRubble;
    world->add(piece);
  }
}

}  // namespace

SiteConfig SiteConfig::scaled_to(const Figure8Path& path) const {
  FlightConfig reference_flight;
  reference_flight.path_length_m = 9.0 * reference_flight.lobe_half_length_m;  // one full lap
  const Figure8Path reference(reference_flight);
  const double factor = (path.lobe_half_length_m() * path.lobe_width_m()) /
                        (reference.lobe_half_length_m() * reference.lobe_width_m());
  if (!(factor > 1.0)) return *this;
  SiteConfig scaled = *this;
  auto grow = [&](int count) { return static_cast<int>(std::lround(count * factor)); };
  scaled.extra_buildings = grow(extra_buildings);
  scaled.rubble_piles = grow(rubble_piles);
  scaled.poles = grow(poles);
  scaled.trees = grow(trees);
  return scaled;
}

Site build_site(const SiteConfig& config, const Figure8Path& path, uint64_t seed) {
  Random random(stream_seed(seed, 0x517E));
  Site site;
  std::vector<Eigen::Vector2d> path_xy;
  for (double s = 0.0; s <= path.length_m(); s += 1.0) path_xy.push_back(path.position_m(s));
  site.low_m = site.high_m = path_xy.front();
  for (const Eigen::Vector2d& p : path_xy) {
    site.low_m = site.low_m.cwiseMin(p);
    site.high_m = site.high_m.cwiseMax(p);
  }
  site.low_m -= Eigen::Vector2d::Constant(config.margin_m);
  site.high_m += Eigen::Vector2d::Constant(config.margin_m);
  const auto path_distance = [&](const Eigen::Vector2d& p) {
    double best = 1e9;
    for (const Eigen::Vector2d& q : path_xy) best = std::min(best, (p - q).norm());
    return best;
  };
  const auto random_point = [&](double inset_m) {
    return Eigen::Vector2d(random.uniform(site.low_m.x() + inset_m, site.high_m.x() - inset_m),
                           random.uniform(site.low_m.y() + inset_m, site.high_m.y() - inset_m));
  };

  site.buildings.push_back(add_passage_building(&site.world, path));
  std::vector<double> heights;
  for (int b = 0, attempts = 0; b < config.extra_buildings && attempts < 2000; ++attempts) {
    const Eigen::Vector2d size(random.uniform(8.0, 16.0), random.uniform(8.0, 14.0));
    const Eigen::Vector2d low = random_point(5.0);
    const Footprint footprint{low, low + size};
    if ((footprint.high_m.array() > site.high_m.array() - 5.0).any()) continue;
    bool clear = true;
    for (const Eigen::Vector2d& q : path_xy)
      clear = clear && distance_to(footprint, q) > config.path_clearance_m + 2.0;
    for (const Footprint& other : site.buildings)
      clear = clear && !overlaps(grown(other, 4.0), footprint);
    if (!clear) continue;
    add_building(&site.world, footprint, random.uniform(3.0, 7.0), &random);
    site.buildings.push_back(footprint);
    ++b;
  }
  const Ground ground(config, site.low_m, site.high_m, site.buildings, &random);
  ground.add_to(&site.world);

  // Small objects: a centre clear of the path by the clearance plus the object's radius, and of
  // buildings and of each other.
  std::vector<std::pair<Eigen::Vector2d, double>> placed;
  const auto find_spot = [&](double radius_m, Eigen::Vector2d* spot) {
    for (int attempt = 0; attempt < 2000; ++attempt) {
      const Eigen::Vector2d p = random_point(3.0);
      if (path_distance(p) < config.path_clearance_m + radius_m) continue;
      bool clear = true;
      for (const Footprint& building : site.buildings)
        clear = clear && distance_to(building, p) > radius_m + 1.5;
      for (const auto& [q, r] : placed) clear = clear && (p - q).norm() > radius_m + r + 1.0;
      if (!clear) continue;
      placed.push_back({p, radius_m});
      *spot = p;
      return true;
    }
    return false;
  };
  Eigen::Vector2d spot;
  for (int i = 0; i < config.rubble_piles; ++i) {
    const double radius = random.uniform(1.5, 2.5);
    if (!find_spot(radius, &spot)) break;
    add_rubble_pile(spot, radius, ground, &random, &site.world);
  }
  for (int i = 0; i < config.poles; ++i) {
    if (!find_spot(0.5, &spot)) break;
    const double base = ground.lowest_near(spot) - 0.3;
    site.world.add(Cylinder{Eigen::Vector3d(spot.x(), spot.y(), base), random.uniform(0.08, 0.15),
                            random.uniform(4.0, 8.0), kPole});
  }
  for (int i = 0; i < config.trees; ++i) {
    const double crown = random.uniform(1.2, 2.2);
    if (!find_spot(crown, &spot)) break;
    const double base = ground.lowest_near(spot) - 0.3;
    const double trunk = random.uniform(2.5, 4.0);
    site.world.add(Cylinder{Eigen::Vector3d(spot.x(), spot.y(), base), random.uniform(0.15, 0.25),
                            trunk + 0.3, kTrunk});
    site.world.add(Sphere{Eigen::Vector3d(spot.x(), spot.y(), base + 0.3 + trunk + 0.6 * crown),
                          crown, kCrown});
  }
  site.world.build();
  return site;
}

}  // namespace sim
}  // namespace covox
