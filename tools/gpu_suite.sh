#!/usr/bin/env bash
# Builds, tests and benchmarks covoxslam on any machine with an NVIDIA GPU, without ROS: the
# library, tools and tests with plain CMake, the whole test suite on both backends, then the
# benchmarks, whose JSON lands in docs/benchmarks/ (and a copy in $OUT), and the generated tables
# of docs/performance.md are rewritten from it.
#
#   tools/gpu_suite.sh [STEP...]          (default: build test bench)
#
# Steps:
#   build                configure and build everything but the ROS layer into $BUILD
#   test                 ctest over the whole suite (GPU tests run where a GPU is usable)
#   bench[:NAME,...]     benchmarks: hash_table, tsdf, esdf_mesh, backend (default: all four)
#   flight               simulate the 1024-column drone flight and map it on the GPU
#                        (docs/benchmarks/pipeline.json)
#   accuracy             the accuracy cases on the GPU with the shipped defaults: simulated flight,
#                        7-Scenes, MulRan, KITTI (docs/benchmarks/accuracy.json; the real-data
#                        cases need COVOX_DATA_DIR); ACCURACY_ARGS="--cases all" runs the whole
#                        matrix (docs/benchmarks/accuracy_matrix.json)
#
# Environment (all optional):
#   CUDA_ARCH                 CUDA architectures; default: the first GPU's compute capability
#                             from nvidia-smi (e.g. 90), else `native`
#   BUILD                     build folder (default build_gpu)
#   OUT                       logs and JSON copies (default ./gpu_suite_out)
#   JOBS                      compile jobs (default: number of cores)
#   COVOX_DATA_DIR            the real sensor data (default: the CMake default)
#   COVOX_EIGEN_INCLUDE_DIR   Eigen's headers, where Eigen is not installed
#   COVOX_GTEST_SOURCE_DIR    GoogleTest's sources, where GoogleTest is not installed
#   BENCH_ARGS                extra arguments for every benchmark
#   ACCURACY_ARGS             extra arguments for benchmark_accuracy (e.g. "--cases all")
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
OUT=${OUT:-$PWD/gpu_suite_out}
BUILD=${BUILD:-build_gpu}
JOBS=${JOBS:-$(nproc)}
mkdir -p "$OUT"

detect_arch() {
  local cap
  cap=$(nvidia-smi --query-gpu=compute_cap --format=csv,noheader 2>/dev/null | head -n 1 | tr -d ' .')
  if [[ "$cap" =~ ^[0-9]+$ ]]; then echo "$cap"; else echo native; fi
}
CUDA_ARCH=${CUDA_ARCH:-$(detect_arch)}

data_args=()
[ -n "${COVOX_DATA_DIR:-}" ] && data_args+=(--data "$COVOX_DATA_DIR")

step_build() {
  local extra=()
  [ -n "${COVOX_DATA_DIR:-}" ] && extra+=(-DCOVOX_DATA_DIR="$COVOX_DATA_DIR")
  [ -n "${COVOX_EIGEN_INCLUDE_DIR:-}" ] && extra+=(-DCOVOX_EIGEN_INCLUDE_DIR="$COVOX_EIGEN_INCLUDE_DIR")
  [ -n "${COVOX_GTEST_SOURCE_DIR:-}" ] && extra+=(-DCOVOX_GTEST_SOURCE_DIR="$COVOX_GTEST_SOURCE_DIR")
  echo "== build ($BUILD, CUDA architectures $CUDA_ARCH)"
  cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release -DCOVOX_WITH_CUDA=ON \
    -DCOVOX_CUDA_ARCHITECTURES="$CUDA_ARCH" -DCOVOX_BUILD_ROS=OFF -DCOVOX_BUILD_TESTS=ON \
    "${extra[@]}" \
    > "$OUT/configure.log" 2>&1 || { tail -30 "$OUT/configure.log"; return 1; }
  local start=$SECONDS
  cmake --build "$BUILD" -j "$JOBS" > "$OUT/build.log" 2>&1 ||
    { grep -B2 -A8 -m5 'error' "$OUT/build.log"; return 1; }
  echo "build: $((SECONDS - start)) s"
}

step_test() {
  # Four tests at a time, each with a quarter of the cores as OpenMP threads: more threads than
  # cores make the CPU twin's many short parallel loops spin against each other.
  local threads=$(( $(nproc) / 4 ))
  [ "$threads" -lt 1 ] && threads=1
  echo "== test"
  (cd "$BUILD" && OMP_NUM_THREADS=$threads ctest --output-on-failure -j 4 --timeout 600 \
    > "$OUT/ctest.log" 2>&1)
  local status=$?
  grep -E "tests passed|tests failed|\(Failed\)|\(Timeout\)|\*\*\*" "$OUT/ctest.log" | head -40
  # A build folder configured without tests (by hand) runs nothing: that is a failure, not a pass.
  if grep -q "No tests were found" "$OUT/ctest.log"; then
    echo "no tests in $BUILD (configured with COVOX_BUILD_TESTS=OFF?)"
    return 1
  fi
  return $status
}

bench_args() {  # NAME -> the arguments its figures in docs/performance.md were taken with
  case "$1" in
    hash_table) echo "--device all" ;;
    tsdf) echo "--device cuda --integrations 100" ;;
    esdf_mesh) echo "--device cuda --updates 30" ;;
    backend) echo "--device cuda --repeats 3 --preconditioner both" ;;
    *) return 1 ;;
  esac
}

step_bench() {  # comma-separated names, or empty for all
  local names status=0
  IFS=, read -ra names <<< "${1:-hash_table,tsdf,esdf_mesh,backend}"
  for name in "${names[@]}"; do
    local args
    args=$(bench_args "$name") || { echo "unknown benchmark $name"; return 2; }
    local extra=()
    [ "$name" = tsdf ] && extra=("${data_args[@]}")
    [ "$name" = esdf_mesh ] && extra=("${data_args[@]}")
    echo "== benchmark_$name $args ${extra[*]} ${BENCH_ARGS:-}"
    # shellcheck disable=SC2086  # word splitting of the argument lists is intended
    "./$BUILD/benchmark_$name" $args "${extra[@]}" ${BENCH_ARGS:-} > "$OUT/benchmark_$name.log" 2>&1 ||
      { echo "benchmark_$name failed:"; tail -20 "$OUT/benchmark_$name.log"; status=1; continue; }
    tail -40 "$OUT/benchmark_$name.log"
  done
  return $status
}

simulate() {  # SEED COLUMNS FOLDER
  [ -f "$3/flight.bag" ] && return 0
  "./$BUILD/simulate_flight" --output-dir "$3" --seed "$1" --columns "$2" > "$3.log" 2>&1 ||
    { echo "simulate_flight failed:"; tail -5 "$3.log"; return 1; }
}

step_flight() {
  echo "== flight (seed 1, 1024 columns, run_slam --device cuda)"
  simulate 1 1024 "$OUT/flight_seed1_1024col" || return 1
  "./$BUILD/run_slam" --bag "$OUT/flight_seed1_1024col/flight.bag" --device cuda --quiet \
    --case "simulated flight seed 1, 1024 columns" --trajectory "$OUT/flight_trajectory.tum" \
    --mesh "$OUT/flight_mesh.ply" --json docs/benchmarks/pipeline.json > "$OUT/run_slam.log" 2>&1 ||
    { tail -20 "$OUT/run_slam.log"; return 1; }
  tail -30 "$OUT/run_slam.log"
}

step_accuracy() {
  echo "== accuracy (benchmark_accuracy --device cuda)"
  local extra=()
  [ -n "${COVOX_DATA_DIR:-}" ] && extra+=(--data-dir "$COVOX_DATA_DIR")
  "./$BUILD/benchmark_accuracy" --device cuda "${extra[@]}" ${ACCURACY_ARGS:-} \
    > "$OUT/benchmark_accuracy.log" 2>&1 || { tail -20 "$OUT/benchmark_accuracy.log"; return 1; }
  tail -30 "$OUT/benchmark_accuracy.log"
}

steps=("$@")
[ ${#steps[@]} -eq 0 ] && steps=(build test bench)
failed=0
for step in "${steps[@]}"; do
  case "$step" in
    build) step_build || exit 1 ;;
    test) step_test || failed=1 ;;
    bench) step_bench "" || failed=1 ;;
    bench:*) step_bench "${step#bench:}" || failed=1 ;;
    flight) step_flight || failed=1 ;;
    accuracy) step_accuracy || failed=1 ;;
    *) echo "unknown step $step (build, test, bench[:NAME,...], flight, accuracy)"; exit 2 ;;
  esac
done
cp docs/benchmarks/*.json "$OUT/" 2>/dev/null
if command -v python3 > /dev/null; then
  python3 tools/scripts/performance_tables.py && cp docs/performance.md "$OUT/"
fi
exit $failed
