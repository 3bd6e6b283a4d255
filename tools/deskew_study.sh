#!/usr/bin/env bash
# The effect of motion distortion and of de-skewing on simulated flights: per seed, the flight
# scanned as a spinning LiDAR scans (each column at its own time; simulate_flight's default) and
# the same flight scanned at once (--instantaneous-scan), mapped by the offline runner with the
# shipped defaults; the distorted flight once more with de-skewing off (a configuration file with
# `deskew: {enabled: false}`: the comparison, not a setting to use). Prints the ATE RMSE (m,
# translation + yaw alignment) and the mesh accuracy (mean distance of the mesh's vertices to the
# world's true surface, m) of each, and writes them as a benchmark report.
#   tools/deskew_study.sh [-b BUILD_DIR] [-o OUTPUT_DIR] [-j REPORT.json] SEED...
# Environment: STUDY_COLUMNS (LiDAR columns, default 256), STUDY_DEVICE (auto|cpu|cuda),
# STUDY_JOBS (seeds mapped side by side, default 1), STUDY_SIM_ARGS (more simulate_flight options,
# e.g. "--duration-s 30 --lobe-half-length-m 12" for a quick look).
set -euo pipefail
build=build
out=deskew_output
report=""
usage="usage: $0 [-b BUILD_DIR] [-o OUTPUT_DIR] [-j REPORT.json] SEED..."
while getopts "b:o:j:" option; do
  case $option in
    b) build=$OPTARG ;;
    o) out=$OPTARG ;;
    j) report=$OPTARG ;;
    *) echo "$usage" >&2; exit 2 ;;
  esac
done
shift $((OPTIND - 1))
[ $# -gt 0 ] || { echo "$usage" >&2; exit 2; }
columns=${STUDY_COLUMNS:-256}
device=${STUDY_DEVICE:-auto}

bin=""
for candidate in "$build" "$build/devel/lib/covoxslam"; do
  [ -x "$candidate/run_slam" ] && [ -x "$candidate/simulate_flight" ] &&
    [ -x "$candidate/evaluate_trajectory" ] && bin=$candidate && break
done
[ -n "$bin" ] || { echo "deskew_study: no run_slam, simulate_flight, evaluate_trajectory in $build" >&2; exit 1; }

mkdir -p "$out"
printf 'deskew:\n  enabled: false\n' > "$out/no_deskew.yaml"
sim_args=${STUDY_SIM_ARGS:-}
export bin out device columns sim_args

# map_flight FLIGHT_DIR LABEL SEED [run_slam options]: maps, evaluates, appends a row to the
# seed's results.
map_flight() {
  local flight=$1 label=$2 seed=$3
  shift 3
  local log="$out/run_slam_${label}_seed$seed.txt"
  "$bin/run_slam" --bag "$flight/flight.bag" --device "$device" --quiet "$@" \
    --trajectory "$out/${label}_seed$seed.tum" --mesh "$out/${label}_seed$seed.ply" > "$log" 2>&1 ||
    { echo "seed $seed $label: run_slam failed:" >&2; tail -3 "$log" >&2; return 1; }
  local odometry covoxslam mesh
  odometry=$(sed -n 's/^  odometry alone *\([0-9.]*\) m RMSE.*/\1/p' "$log")
  covoxslam=$(sed -n 's/^  covoxslam *\([0-9.]*\) m RMSE.*/\1/p' "$log")
  mesh=$("$bin/evaluate_trajectory" --mesh "$out/${label}_seed$seed.ply" \
    --gt-mesh "$flight/world.ply" | sed -n 's/^accuracy: mean \([0-9.e-]*\) m.*/\1/p')
  printf '%s\t%s\t%s\t%s\t%s\n' "$seed" "$label" "${odometry:-nan}" "${covoxslam:-nan}" \
    "${mesh:-nan}" >> "$out/rows_seed$seed.tsv"
  echo "seed $seed $label: odometry ${odometry:-?} m, covoxslam ${covoxslam:-?} m, mesh ${mesh:-?} m" >&2
}

# study_seed SEED: both scans of the flight, the three mappings.
study_seed() {
  local seed=$1 scan flight
  # A seed whose three mappings are done is not mapped again (a study stopped halfway resumes).
  [ -f "$out/rows_seed$seed.tsv" ] && [ "$(wc -l < "$out/rows_seed$seed.tsv")" -eq 3 ] && return 0
  : > "$out/rows_seed$seed.tsv"
  for scan in distorted instantaneous; do
    flight="$out/flight_seed${seed}_${columns}col_$scan"
    if [ ! -f "$flight/flight.bag" ]; then
      local extra=()
      read -r -a extra <<< "$sim_args"
      [ "$scan" = instantaneous ] && extra+=(--instantaneous-scan)
      "$bin/simulate_flight" --output-dir "$flight" --seed "$seed" --columns "$columns" \
        "${extra[@]}" > "$out/simulate_${scan}_seed$seed.txt" 2>&1 ||
        { echo "seed $seed: simulate_flight failed:" >&2; tail -3 "$out/simulate_${scan}_seed$seed.txt" >&2; return 1; }
    fi
  done
  map_flight "$out/flight_seed${seed}_${columns}col_instantaneous" instantaneous "$seed"
  map_flight "$out/flight_seed${seed}_${columns}col_distorted" deskewed "$seed"
  map_flight "$out/flight_seed${seed}_${columns}col_distorted" not_deskewed "$seed" \
    --config "$out/no_deskew.yaml"
}
export -f map_flight study_seed

# Seeds side by side (the GPU and the cores are shared; each flight's result is its own).
printf '%s\n' "$@" | xargs -P "${STUDY_JOBS:-1}" -I{} bash -c 'study_seed {}' ||
  { echo "deskew_study: a seed failed (see above and $out)" >&2; exit 1; }
results="$out/results.tsv"
for seed in "$@"; do cat "$out/rows_seed$seed.tsv"; done > "$results"
if grep -q nan "$results"; then
  echo "deskew_study: a mapping gave no figure (see the logs in $out)" >&2
  exit 1
fi

device_name=$(sed -n 's/^device: //p' "$out/run_slam_deskewed_seed$1.txt" | head -n 1)
python3 - "$results" "$report" "$device_name" "$columns" "$0 $*" <<'PY'
import datetime, json, sys
rows_path, report, device, columns, command = sys.argv[1:6]
rows = [line.rstrip("\n").split("\t") for line in open(rows_path) if line.strip()]
labels = ["instantaneous", "deskewed", "not_deskewed"]
table = {}
for seed, label, odometry, ate, mesh in rows:
    table.setdefault(seed, {})[label] = (float(odometry), float(ate), float(mesh))
print(f"device: {device}; {columns} columns; ATE RMSE (m) / mesh accuracy mean (m)")
print("%6s %10s %22s %22s %22s" % ("seed", "odometry", *labels))
means = {label: [0.0, 0.0] for label in labels}
for seed, by_label in table.items():
    cells = []
    for label in labels:
        _, ate, mesh = by_label[label]
        means[label][0] += ate / len(table)
        means[label][1] += mesh / len(table)
        cells.append("%10.3f / %9.4f" % (ate, mesh))
    print("%6s %10.3f %22s %22s %22s" % (seed, by_label["deskewed"][0], *cells))
print("%6s %10s %22s %22s %22s" % ("mean", "", *["%10.3f / %9.4f" % tuple(means[l]) for l in labels]))
if report:
    results = []
    for seed, by_label in table.items():
        results.append({"case": f"seed {seed}", "metric": "ATE RMSE odometry",
                        "value": by_label["deskewed"][0], "unit": "m"})
        for label in labels:
            _, ate, mesh = by_label[label]
            name = label.replace("_", " ")
            results.append({"case": f"seed {seed}", "metric": f"ATE RMSE {name}", "value": ate, "unit": "m"})
            results.append({"case": f"seed {seed}", "metric": f"mesh accuracy mean {name}", "value": mesh, "unit": "m"})
    for label in labels:
        name = label.replace("_", " ")
        results.append({"case": "mean", "metric": f"ATE RMSE {name}", "value": means[label][0], "unit": "m"})
        results.append({"case": "mean", "metric": f"mesh accuracy mean {name}", "value": means[label][1], "unit": "m"})
    with open(report, "w") as f:
        json.dump({"benchmark": "deskew", "device": device,
                   "date": datetime.date.today().isoformat(), "command": command,
                   "results": results}, f, indent=2)
        f.write("\n")
    print(f"report -> {report}")
PY
