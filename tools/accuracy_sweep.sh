#!/usr/bin/env bash
# Simulated flights, one per seed: simulates each flight (cached in the output folder), maps it
# with the offline runner (arche preset) and prints a table of the odometry's and covoxslam's
# ATE RMSE against the ground truth (translation + yaw alignment, as run_slam reports it).
#   tools/accuracy_sweep.sh [-b BUILD_DIR] [-o OUTPUT_DIR] SEED...
# Environment: SWEEP_COLUMNS (LiDAR columns, default 256 as make demo), SWEEP_DEVICE
# (auto|cpu|cuda, default auto), SWEEP_ARGS (more run_slam arguments, e.g. "--config F" to map
# the flights with settings of F over the preset's).
set -euo pipefail
build=build
out=sweep_output
while getopts "b:o:" option; do
  case $option in
    b) build=$OPTARG ;;
    o) out=$OPTARG ;;
    *) echo "usage: $0 [-b BUILD_DIR] [-o OUTPUT_DIR] SEED..." >&2; exit 2 ;;
  esac
done
shift $((OPTIND - 1))
[ $# -gt 0 ] || { echo "usage: $0 [-b BUILD_DIR] [-o OUTPUT_DIR] SEED..." >&2; exit 2; }
columns=${SWEEP_COLUMNS:-256}
device=${SWEEP_DEVICE:-auto}
read -r -a extra_args <<< "${SWEEP_ARGS:-}"

bin=""
for candidate in "$build" "$build/devel/lib/covoxslam"; do
  [ -x "$candidate/run_slam" ] && [ -x "$candidate/simulate_flight" ] && bin=$candidate && break
done
[ -n "$bin" ] || { echo "accuracy_sweep: no run_slam and simulate_flight in $build" >&2; exit 1; }

mkdir -p "$out"
rows=()
for seed in "$@"; do
  flight="$out/flight_seed${seed}_${columns}col"
  if [ ! -f "$flight/flight.bag" ]; then
    "$bin/simulate_flight" --output-dir "$flight" --seed "$seed" --columns "$columns" \
      > "$out/simulate_seed$seed.txt" 2>&1
  fi
  log="$out/run_slam_seed$seed.txt"
  "$bin/run_slam" --bag "$flight/flight.bag" --device "$device" --quiet "${extra_args[@]}" \
    --trajectory "$out/covoxslam_seed$seed.tum" --mesh "$out/mesh_seed$seed.ply" > "$log"
  odometry=$(sed -n 's/^  odometry alone *\([0-9.]*\) m RMSE.*/\1/p' "$log")
  covoxslam=$(sed -n 's/^  covoxslam *\([0-9.]*\) m RMSE.*/\1/p' "$log")
  rows+=("$(printf '%6s %14s %15s' "$seed" "${odometry:-?}" "${covoxslam:-?}")")
  echo "seed $seed: odometry ${odometry:-?} m, covoxslam ${covoxslam:-?} m" >&2
done

echo "device: $(sed -n 's/^device: //p' "$out/run_slam_seed$1.txt")"
printf '%6s %14s %15s\n' seed odometry_ate_m covoxslam_ate_m
printf '%s\n' "${rows[@]}"
