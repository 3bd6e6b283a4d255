#!/usr/bin/env bash
# Side-by-side comparison of the TSDF benchmark built from two trees on one GPU host: builds
# benchmark_tsdf from a base tree (a `git archive` of the base revision unpacked in BASE_DIR,
# built in build_base/ here, outside BASE_DIR, so that replacing BASE_DIR keeps the build) and
# from this tree (build_gpu/, the whole suite), then runs the two alternately RUNS times each,
# so that both see the same machine state, and once more each with the stage profile
# (COVOX_PROFILE_STAGES). Per-run JSON and logs go to $OUT/ab/; the medians per case are printed by tools/scripts/ab_table.py.
#   tools/device/ab_tsdf.sh BASE_DIR [RUNS] [benchmark_tsdf args...]
set -uo pipefail
cd "$(dirname "$0")/../.."
BASE_DIR=$1; shift
RUNS=${1:-3}; shift || true
OUT=${OUT:-/tmp/covox_out}
mkdir -p "$OUT/ab"
export COVOX_DATA_DIR=${COVOX_DATA_DIR:-$PWD/.device_data}
configure() {  # source dir, build dir
  cmake -S "$1" -B "$2" -DCMAKE_BUILD_TYPE=Release -DCOVOX_CUDA_ARCHITECTURES=90 -DCOVOX_BUILD_ROS=OFF \
    -DCOVOX_DATA_DIR="$COVOX_DATA_DIR" > "$OUT/ab/configure_$(basename "$2").log" 2>&1
}
# A build_base left by an earlier run may have been configured from another base tree.
if [ -f build_base/CMakeCache.txt ] &&
   ! grep -q "^CMAKE_HOME_DIRECTORY:INTERNAL=$(cd "$BASE_DIR" && pwd)$" build_base/CMakeCache.txt; then
  rm -rf build_base
fi
configure "$BASE_DIR" build_base && configure . build_gpu || { echo "configure failed"; tail -5 "$OUT"/ab/configure_*.log; exit 1; }
jobs=$(( $(nproc) / 2 ))
cmake --build build_base -j "$jobs" --target benchmark_tsdf > "$OUT/ab/build_base.log" 2>&1 &
base_build=$!
cmake --build build_gpu -j "$jobs" > "$OUT/ab/build_new.log" 2>&1 || { grep -B2 -A8 -m5 error "$OUT/ab/build_new.log"; exit 1; }
wait $base_build || { grep -B2 -A8 -m5 error "$OUT/ab/build_base.log"; exit 1; }
bench() {  # side, output name, extra args
  local binary=./build_gpu/benchmark_tsdf
  [ "$1" = base ] && binary=./build_base/benchmark_tsdf
  "$binary" --device cuda --data "$COVOX_DATA_DIR" --output "$OUT/ab/$2.json" "${@:3}" > "$OUT/ab/$2.log" 2>&1 ||
    { echo "$2 failed:"; tail -3 "$OUT/ab/$2.log"; }
}
for run in $(seq 1 "$RUNS"); do
  bench base "base_$run" "$@"
  bench new "new_$run" "$@"
done
if [ "$RUNS" -gt 0 ]; then
  COVOX_PROFILE_STAGES=1 bench base profile_base "$@"
  COVOX_PROFILE_STAGES=1 bench new profile_new "$@"
  python3 tools/scripts/ab_table.py "$OUT/ab"
fi
echo "A/B done: $RUNS runs each"
