#!/usr/bin/env bash
# Builds the non-ROS library, tests and benchmarks on a GPU host without ROS, runs the test suite
# and the benchmarks, and leaves logs and JSON under $OUT.
#   tools/device/gpu_suite.sh [build|test|bench:NAME[,NAME...]]...   (default: build test)
# Expects Eigen and GoogleTest sources in .device_deps/ and the data subset in .device_data/
# when they are not installed there.
set -uo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-/tmp/covox_out}
mkdir -p "$OUT"
BUILD=${BUILD:-build_gpu}
export COVOX_DATA_DIR=${COVOX_DATA_DIR:-$PWD/.device_data}
steps=("$@")
[ ${#steps[@]} -eq 0 ] && steps=(build test)
for step in "${steps[@]}"; do
  case "$step" in
    build)
      extra=()
      [ -d .device_deps/eigen3 ] && extra+=(-DCOVOX_EIGEN_INCLUDE_DIR=$PWD/.device_deps/eigen3)
      [ -d .device_deps/googletest ] && extra+=(-DCOVOX_GTEST_SOURCE_DIR=$PWD/.device_deps/googletest)
      cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release -DCOVOX_CUDA_ARCHITECTURES=90 -DCOVOX_BUILD_ROS=OFF \
        -DCOVOX_DATA_DIR="$COVOX_DATA_DIR" "${extra[@]}" > "$OUT/configure.log" 2>&1 || { tail -30 "$OUT/configure.log"; exit 1; }
      start=$(date +%s)
      cmake --build "$BUILD" -j "$(nproc)" > "$OUT/build.log" 2>&1 || { grep -B2 -A8 -m5 'error' "$OUT/build.log"; exit 1; }
      echo "build: $(( $(date +%s) - start )) s"
      ;;
    test)
      # Four tests at a time with four OpenMP threads each: more threads than cores makes the
      # CPU twin's many short parallel loops spin against each other, each test waiting mostly on
      # the others.
      (cd "$BUILD" && OMP_NUM_THREADS=4 ctest --output-on-failure -j 4 --timeout 600 > "$OUT/ctest.log" 2>&1)
      grep -E "tests passed|tests failed|\(Failed\)|\(Timeout\)|\*\*\*" "$OUT/ctest.log" | head -40
      ;;
    bench:*)
      IFS=, read -ra names <<< "${step#bench:}"
      mkdir -p docs/benchmarks
      for name in "${names[@]}"; do
        echo "== benchmark_$name"
        "./$BUILD/benchmark_$name" ${BENCH_ARGS:-} > "$OUT/benchmark_$name.log" 2>&1
        echo "rc=$?"; tail -60 "$OUT/benchmark_$name.log"
      done
      cp docs/benchmarks/*.json "$OUT/" 2>/dev/null
      ;;
    *) echo "unknown step $step"; exit 2 ;;
  esac
done
