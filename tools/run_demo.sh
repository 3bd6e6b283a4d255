#!/usr/bin/env bash
# The README's main command (`make demo`): simulates the default drone flight once (an ARCHE-like
# rosbag, cached in the output folder), runs the SLAM on it with the offline runner (GPU if one
# is usable, the CPU twin otherwise), and prints the summary: ATE RMSE of the odometry alone and
# of covoxslam against the ground truth (translation + yaw alignment, as the ARCHE evaluation),
# per-module timings and the map size. Writes the mesh (PLY) and a trajectory plot (PNG).
#   tools/run_demo.sh [BUILD_DIR] [OUTPUT_DIR]
# Settings (environment): DEMO_COLUMNS (LiDAR columns, default 256 so that the CPU twin maps the
# whole flight in minutes; 1024 is the real OS1-64), DEMO_DEVICE (auto|cpu|cuda), DEMO_SEED.
# run_slam maps a bag with the arche preset (config/arche.yaml); the flight bag is what
# launch/arche.launch plays for the rviz variant (its default config, the same file).
set -euo pipefail
build=${1:-build}
out=${2:-demo_output}
columns=${DEMO_COLUMNS:-256}
device=${DEMO_DEVICE:-auto}
seed=${DEMO_SEED:-1}

# Plain CMake puts the programs in the build folder, catkin in its devel space.
bin=""
for candidate in "$build" "$build/devel/lib/covoxslam"; do
  [ -x "$candidate/run_slam" ] && bin=$candidate && break
done
[ -n "$bin" ] || { echo "run_demo: no run_slam in $build; run 'make build' first" >&2; exit 1; }

mkdir -p "$out"
flight="$out/flight_seed${seed}_${columns}col"
# A flight cached before the simulator distorted its scans (its log has no `motion:` line) is
# simulated again: it would map clouds a real flight never produces.
if [ -f "$flight/flight.bag" ] && ! grep -q '^motion:' "$out/simulate_flight.txt" 2>/dev/null; then
  echo "== the cached flight in $flight predates the distorting simulator: simulating it again"
  rm -f "$flight/flight.bag"
fi
if [ ! -f "$flight/flight.bag" ]; then
  echo "== simulating the default flight (seed $seed, $columns LiDAR columns; cached in $flight)"
  "$bin/simulate_flight" --output-dir "$flight" --seed "$seed" --columns "$columns" | tee "$out/simulate_flight.txt"
else
  echo "== using the cached flight $flight/flight.bag"
fi

echo "== covoxslam on the flight (device: $device)"
"$bin/run_slam" --bag "$flight/flight.bag" --device "$device" --trajectory "$out/covoxslam.tum" \
  --odometry-trajectory "$out/odometry.tum" --mesh "$out/mesh.ply" --json "$out/pipeline.json" \
  --case "simulated flight seed $seed, $columns columns" | tee "$out/run_slam.txt"

echo "== trajectories against the ground truth"
"$bin/evaluate_trajectory" --reference "$flight/truth.tum" --estimate "$out/odometry.tum,$out/covoxslam.tum" \
  --labels odometry,covoxslam --align 4dof --plot "$out/trajectory.png" | tee "$out/trajectory.txt"

# The summary, taken from the runner's report.
odometry_ate=$(sed -n 's/^  odometry alone *\([0-9.]*\) m RMSE.*/\1/p' "$out/run_slam.txt")
covoxslam_ate=$(sed -n 's/^  covoxslam *\([0-9.]*\) m RMSE.*/\1/p' "$out/run_slam.txt")
drift=$(sed -n 's/^odometry drift: final \([0-9.]*\) m.*/\1/p' "$out/simulate_flight.txt" 2>/dev/null || true)
cat <<SUMMARY

== demo finished
$(sed -n 's/^device: /  device:            /p' "$out/run_slam.txt")
  odometry drift:    ${drift:-see $out/simulate_flight.txt} m at the end of the flight
  ATE RMSE (translation + yaw alignment, against the ground truth):
    odometry alone   ${odometry_ate:-?} m
    covoxslam        ${covoxslam_ate:-?} m
  timings:
$(sed -n '/^module /,/^total wall/p' "$out/run_slam.txt" | sed 's/^/    /')
$(sed -n 's/^map: /  map:               /p' "$out/run_slam.txt")
$(sed -n 's/^de-skewing: /  de-skewing:        /p' "$out/run_slam.txt")
  mesh:              $out/mesh.ply (ground truth: $flight/world.ply)
  trajectory plot:   $out/trajectory.png
  flight bag:        $flight/flight.bag (rosbag play-able, ARCHE topics)
  in rviz (ROS), from the repository root in any shell:
    make ros && source build/devel/setup.bash && roslaunch covoxslam arche.launch bag:=$(cd "$flight" && pwd)/flight.bag rviz:=true
SUMMARY
