#!/usr/bin/env bash
# Side-by-side comparison of benchmark_tsdf built from several source trees on one GPU host (the
# N-way form of ab_tsdf.sh): each tree (a `git archive` of a revision, or a copy of this tree
# with one change, unpacked under the git-ignored .snapshot/ and copied to the host) is
# built in build_ab_NAME/ (benchmark_tsdf only, the builds side by side), then the binaries run
# in turn RUNS times each, so that all see the same machine state. Per-run JSON and logs go to
# $OUT/ab/ as NAME_RUN.json; tools/scripts/ab_table.py prints the medians per case against the
# first tree.
#   tools/device/ab_trees.sh RUNS NAME=DIR [NAME=DIR ...] [-- benchmark_tsdf args...]
set -uo pipefail
cd "$(dirname "$0")/../.."
RUNS=$1
shift
names=()
dirs=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do
  names+=("${1%%=*}")
  dirs+=("${1#*=}")
  shift
done
[ "${1:-}" = "--" ] && shift
[ ${#names[@]} -ge 1 ] || { echo "usage: ab_trees.sh RUNS NAME=DIR... [-- args]"; exit 2; }
OUT=${OUT:-/tmp/covox_out}
mkdir -p "$OUT/ab"
export COVOX_DATA_DIR=${COVOX_DATA_DIR:-$PWD/.device_data}
jobs=$(( $(nproc) / ${#names[@]} ))
[ "$jobs" -lt 2 ] && jobs=2
start=$(date +%s)
pids=()
for k in "${!names[@]}"; do
  (
    source_dir=$(cd "${dirs[$k]}" && pwd)
    build=build_ab_${names[$k]}
    # A build folder left by an earlier run may have been configured from another tree.
    if [ -f "$build/CMakeCache.txt" ] && ! grep -q "^CMAKE_HOME_DIRECTORY:INTERNAL=$source_dir$" "$build/CMakeCache.txt"; then
      rm -rf "$build"
    fi
    cmake -S "$source_dir" -B "$build" -DCMAKE_BUILD_TYPE=Release -DCOVOX_CUDA_ARCHITECTURES=90 -DCOVOX_BUILD_ROS=OFF \
      -DCOVOX_BUILD_TESTS=OFF -DCOVOX_DATA_DIR="$COVOX_DATA_DIR" > "$OUT/ab/configure_${names[$k]}.log" 2>&1 &&
      cmake --build "$build" -j "$jobs" --target benchmark_tsdf > "$OUT/ab/build_${names[$k]}.log" 2>&1
  ) &
  pids+=($!)
done
failed=0
for k in "${!pids[@]}"; do
  if ! wait "${pids[$k]}"; then
    echo "build of ${names[$k]} failed:"
    grep -B2 -A8 -m5 error "$OUT/ab/build_${names[$k]}.log" "$OUT/ab/configure_${names[$k]}.log" | head -40
    failed=1
  fi
done
echo "builds: $(( $(date +%s) - start )) s"
[ "$failed" -eq 0 ] || exit 1
for run in $(seq 1 "$RUNS"); do
  for name in "${names[@]}"; do
    ./build_ab_$name/benchmark_tsdf --device cuda --data "$COVOX_DATA_DIR" --output "$OUT/ab/${name}_$run.json" "$@" \
      > "$OUT/ab/${name}_$run.log" 2>&1 || { echo "$name run $run failed:"; tail -3 "$OUT/ab/${name}_$run.log"; }
  done
done
python3 tools/scripts/ab_table.py "$OUT/ab" --sides "$(IFS=,; echo "${names[*]}")"
echo "runs done: $RUNS each, $(( $(date +%s) - start )) s"
