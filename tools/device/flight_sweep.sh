#!/usr/bin/env bash
# ATE of the simulated flight over seeds, resolutions and parameter variants, in one table.
#   tools/device/flight_sweep.sh BUILD_DIR WORK_DIR "SEEDS" "COLUMNS" preset|VARIANT.yaml ...
# Simulates each (seed, columns) flight once (kept in WORK_DIR/bags, reused by later calls), runs
# `run_slam` with each VARIANT.yaml applied over the ARCHE preset (`--config`; the word `preset`
# for the preset alone), JOBS runs at a time (default 1: the runs are deterministic, but processes
# sharing one GPU slow each other down by more than they run in parallel), and prints one row per
# variant: ATE RMSE per flight, the mean and the worst. Logs, trajectories and graph dumps stay in
# WORK_DIR/runs.
# Example: tools/device/flight_sweep.sh build_gpu $OUT/sweep "1 2 3 4 5" "256 1024" preset v/*.yaml
set -uo pipefail
build=$1 work=$2 seeds=$3 columns=$4
shift 4
variants=("$@")
jobs=${JOBS:-1}
device=${DEVICE:-auto}
mkdir -p "$work/bags" "$work/runs"

for c in $columns; do
  for s in $seeds; do
    bag="$work/bags/s${s}c${c}"
    [ -f "$bag/flight.bag" ] && continue
    "$build/simulate_flight" --output-dir "$bag" --seed "$s" --columns "$c" > "$bag.log" 2>&1 ||
      { echo "simulate_flight seed $s columns $c failed:"; tail -5 "$bag.log"; exit 1; }
  done
done

run_one() {  # variant seed columns
  local v=$1 s=$2 c=$3 name extra=()
  name=$(basename "$v" .yaml)
  [ "$v" != preset ] && extra=(--config "$v")
  local stem="$work/runs/${name}_s${s}c${c}"
  "$build/run_slam" --bag "$work/bags/s${s}c${c}/flight.bag" --device "$device" --quiet "${extra[@]}" \
    --trajectory "$stem.tum" --mesh /dev/null --graph "$stem.graph.txt" > "$stem.log" 2>&1
}
export -f run_one
export work build device
for v in "${variants[@]}"; do for c in $columns; do for s in $seeds; do echo "$v $s $c"; done; done; done |
  xargs -P "$jobs" -L 1 bash -c 'run_one "$0" "$1" "$2"'

# The table: ATE RMSE (m) of covoxslam per flight, "fail" where the run did not finish.
header="| variant |"
rule="|---|"
for c in $columns; do for s in $seeds; do header+=" s$s c$c |"; rule+="---:|"; done; done
echo "$header mean | worst |"
echo "$rule---:|---:|"
for v in "${variants[@]}"; do
  name=$(basename "$v" .yaml)
  row="| $name |"
  values=()
  for c in $columns; do for s in $seeds; do
    ate=$(awk '/^  covoxslam/ {print $2}' "$work/runs/${name}_s${s}c${c}.log" 2>/dev/null)
    row+=" ${ate:-fail} |"
    [ -n "$ate" ] && values+=("$ate")
  done; done
  stats=$(printf '%s\n' "${values[@]}" | awk 'NF {n++; t+=$1; if ($1 > m) m = $1} END {if (n) printf "%.3f | %.3f", t/n, m; else print "- | -"}')
  echo "$row $stats |"
done
