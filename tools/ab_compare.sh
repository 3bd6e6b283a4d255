#!/usr/bin/env bash
# Same-run comparison of one benchmark built from several source trees on one GPU machine.
# Machines of one kind differ by several per cent and drift within minutes, so two builds are
# only compared when their runs alternate on the same machine: each side is built (the builds
# side by side), then the binaries run in turn RUNS times each, and
# tools/scripts/ab_table.py prints each case's median per side and its ratio to the first side.
#
#   tools/ab_compare.sh [-n RUNS] [-b BENCHMARK] [-m METRIC] NAME=SOURCE NAME=SOURCE... [-- ARGS...]
#
#   SOURCE     a directory holding a source tree, or a git revision of this repository (exported
#              with `git archive` into $OUT/ab/trees/NAME)
#   RUNS       runs per side (default 5)
#   BENCHMARK  tsdf (default), hash_table or backend: those that take --output
#   METRIC     the metric compared (default "median integration time")
#   ARGS       the benchmark's arguments (default for tsdf: --device cuda --integrations 100)
#
# Example: tools/ab_compare.sh base=HEAD~1 new=. -- --device cuda --integrations 100 --skip-lidar
# Environment: CUDA_ARCH (default: detected as tools/gpu_suite.sh does), OUT (default
# ./gpu_suite_out), COVOX_DATA_DIR (passed to the benchmark as --data when set).
# Per-run JSON and logs are left in $OUT/ab/ as NAME_RUN.json and NAME_RUN.log.
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
RUNS=5
BENCHMARK=tsdf
METRIC="median integration time"
while getopts "n:b:m:" option; do
  case "$option" in
    n) RUNS=$OPTARG ;;
    b) BENCHMARK=$OPTARG ;;
    m) METRIC=$OPTARG ;;
    *) exit 2 ;;
  esac
done
shift $((OPTIND - 1))
names=()
sources=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do
  [[ "$1" == *=* ]] || { echo "expected NAME=SOURCE, got '$1'"; exit 2; }
  names+=("${1%%=*}")
  sources+=("${1#*=}")
  shift
done
[ "${1:-}" = "--" ] && shift
args=("$@")
if [ ${#args[@]} -eq 0 ] && [ "$BENCHMARK" = tsdf ]; then
  args=(--device cuda --integrations 100)
fi
[ -n "${COVOX_DATA_DIR:-}" ] && args+=(--data "$COVOX_DATA_DIR")
[ ${#names[@]} -ge 2 ] || { echo "usage: ab_compare.sh [-n RUNS] [-b BENCHMARK] NAME=SOURCE NAME=SOURCE... [-- ARGS]"; exit 2; }

OUT=${OUT:-$PWD/gpu_suite_out}
mkdir -p "$OUT/ab/trees"
cap=$(nvidia-smi --query-gpu=compute_cap --format=csv,noheader 2>/dev/null | head -n 1 | tr -d ' .')
[[ "$cap" =~ ^[0-9]+$ ]] || cap=native
CUDA_ARCH=${CUDA_ARCH:-$cap}

source_dir() {  # NAME SOURCE -> an absolute source directory
  if [ -d "$2" ]; then
    (cd "$2" && pwd)
    return
  fi
  local dir="$OUT/ab/trees/$1"
  rm -rf "$dir" && mkdir -p "$dir"
  git archive "$2" | tar -x -C "$dir" || return 1
  echo "$dir"
}

jobs=$(( $(nproc) / ${#names[@]} ))
[ "$jobs" -lt 2 ] && jobs=2
start=$SECONDS
pids=()
for k in "${!names[@]}"; do
  (
    dir=$(source_dir "${names[$k]}" "${sources[$k]}") || exit 1
    build=build_ab_${names[$k]}
    # A build folder configured from another source tree is started afresh.
    if [ -f "$build/CMakeCache.txt" ] &&
       ! grep -q "^CMAKE_HOME_DIRECTORY:INTERNAL=$dir$" "$build/CMakeCache.txt"; then
      rm -rf "$build"
    fi
    cmake -S "$dir" -B "$build" -DCMAKE_BUILD_TYPE=Release -DCOVOX_WITH_CUDA=ON \
      -DCOVOX_CUDA_ARCHITECTURES="$CUDA_ARCH" -DCOVOX_BUILD_ROS=OFF -DCOVOX_BUILD_TESTS=OFF \
      > "$OUT/ab/configure_${names[$k]}.log" 2>&1 &&
      cmake --build "$build" -j "$jobs" --target "benchmark_$BENCHMARK" \
        > "$OUT/ab/build_${names[$k]}.log" 2>&1
  ) &
  pids+=($!)
done
failed=0
for k in "${!pids[@]}"; do
  if ! wait "${pids[$k]}"; then
    echo "build of ${names[$k]} failed:"
    grep -B2 -A8 -m5 error "$OUT/ab/configure_${names[$k]}.log" "$OUT/ab/build_${names[$k]}.log" | head -40
    failed=1
  fi
done
echo "builds: $((SECONDS - start)) s"
[ "$failed" -eq 0 ] || exit 1
for run in $(seq 1 "$RUNS"); do
  for name in "${names[@]}"; do
    "./build_ab_$name/benchmark_$BENCHMARK" "${args[@]}" --output "$OUT/ab/${name}_$run.json" \
      > "$OUT/ab/${name}_$run.log" 2>&1 ||
      { echo "$name run $run failed:"; tail -3 "$OUT/ab/${name}_$run.log"; }
  done
done
python3 tools/scripts/ab_table.py "$OUT/ab" --sides "$(IFS=,; echo "${names[*]}")" --metric "$METRIC"
