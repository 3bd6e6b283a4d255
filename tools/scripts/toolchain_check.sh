#!/usr/bin/env bash
# Checks, without a Jetson, that the library builds with the toolchain of a JetPack 5 robot
# (Ubuntu 20.04: CMake 3.16.3, GCC 9.4 and its libstdc++, CUDA 11.4, sm_72 Xavier / sm_87 Orin):
#
#   1. configures with CMake 3.16.3 (PyPI `cmake==3.16.3.post1`, in a venv);
#   2. compiles every CUDA source with nvcc 11.8 (Debian's non-free nvidia-cuda-toolkit, with
#      CUDA 11.8's Thrust/CUB headers from PyPI) and g++-11 for sm_72 and sm_87;
#   3. compiles every C++ source of the library with clang 14 against libc++ 14 in C++17 mode: a
#      standard library that, like GCC 9's, has no floating-point std::from_chars and none of
#      C++20's library;
#   4. greps the sources for library features GCC 9.4 lacks that libc++ 14 would let through.
#
#   tools/scripts/toolchain_check.sh [STEP...]     steps: setup cuda cxx grep (default: all)
#
# Installs what it needs (Debian packages through apt, the rest into the cache folder); downloads
# are kept in COVOX_TOOLCHAIN_CACHE (default ~/.cache/covoxslam-toolchain), which CI may reuse.
# Nothing in /usr changes apart from the Debian packages. Environment (optional):
#   COVOX_TOOLCHAIN_CACHE   the cache folder
#   BUILD                   build folders' parent (default build_toolchain)
#   JOBS                    compile jobs (default: number of cores)
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
CACHE=${COVOX_TOOLCHAIN_CACHE:-$HOME/.cache/covoxslam-toolchain}
BUILD=${BUILD:-$PWD/build_toolchain}
JOBS=${JOBS:-$(nproc 2>/dev/null || echo 2)}
CUDA_ARCHITECTURES="72;87"
VENV=$CACHE/venv
TOOLKIT=$CACHE/cuda-11.8
CMAKE=$VENV/bin/cmake
# libc++'s and libomp's headers are unpacked into the cache rather than installed: libc++-14-dev
# pulls libunwind-14-dev, which conflicts with libunwind-dev (needed by glog, and so by Ceres).
DEBIAN_PACKAGES="g++-11 clang-14 libeigen3-dev python3-venv make"
LIBCXX=$CACHE/libcxx

say() { echo "toolchain-check: $*"; }

install_debian_packages() {
  local missing=() p
  for p in $DEBIAN_PACKAGES; do
    dpkg-query -W -f='${Status}\n' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return
  say "installing Debian packages: ${missing[*]}"
  local sudo=""
  [ "$(id -u)" = 0 ] || sudo=sudo
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

install_python_packages() {
  [ -x "$CMAKE" ] && [ -f "$VENV/.complete" ] && return
  say "installing CMake 3.16.3 and CUDA 11.8's headers into $VENV"
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q cmake==3.16.3.post1 nvidia-cuda-runtime-cu11==11.8.89 \
    nvidia-cuda-cccl-cu11==11.8.89 nvidia-cuda-nvcc-cu11==11.8.89
  touch "$VENV/.complete"
}

# nvcc, cicc and the other compiler programs come from Debian's non-free archive, libc++'s
# headers from main; downloaded through a private package list so the system's sources stay as
# they are.
download_debian_packages() {
  local apt=$CACHE/apt debs=$CACHE/debs
  [ -f "$debs/.complete" ] && return
  say "downloading nvidia-cuda-toolkit (CUDA 11.8, non-free), libc++ 14 and libomp 14 headers"
  mkdir -p "$apt/lists/partial" "$debs"
  echo "deb http://deb.debian.org/debian bookworm main contrib non-free" >"$apt/sources.list"
  local options=(-o "Dir::Etc::sourcelist=$apt/sources.list" -o "Dir::Etc::sourceparts=-"
    -o "Dir::State::Lists=$apt/lists" -o "Dir::Cache=$apt/cache" -o "APT::Sandbox::User=root")
  apt-get "${options[@]}" update -qq
  (cd "$debs" && apt-get "${options[@]}" download nvidia-cuda-toolkit libnvvm4 libc++-14-dev \
    libc++abi-14-dev libomp-14-dev)
  touch "$debs/.complete"
}

# libc++ 14's and libomp 14's headers, for compiling (never linking) against libc++.
unpack_libcxx() {
  [ -f "$LIBCXX/.complete" ] && return
  rm -rf "$LIBCXX"
  mkdir -p "$LIBCXX/root" "$LIBCXX/omp"
  local deb
  for deb in "$CACHE"/debs/libc++*.deb "$CACHE"/debs/libomp-14-dev*.deb; do dpkg -x "$deb" "$LIBCXX/root"; done
  cp "$(find "$LIBCXX/root" -name omp.h | head -1)" "$LIBCXX/omp/"
  touch "$LIBCXX/.complete"
}

# A self-contained toolkit folder: Debian's compiler programs and libnvvm, PyPI's headers,
# runtime library and ptxas, and an nvcc.profile that points nvcc at them.
assemble_toolkit() {
  [ -f "$TOOLKIT/.complete" ] && return
  say "assembling CUDA 11.8 in $TOOLKIT"
  rm -rf "$TOOLKIT" "$CACHE/root"
  local deb root=$CACHE/root
  for deb in "$CACHE"/debs/nvidia-cuda-toolkit*.deb "$CACHE"/debs/libnvvm4*.deb; do
    dpkg -x "$deb" "$root"
  done
  mkdir -p "$TOOLKIT/bin" "$TOOLKIT/nvvm/lib64" "$TOOLKIT/include" "$TOOLKIT/lib64"
  local libexec=$root/usr/lib/nvidia-cuda-toolkit program
  cp -a "$libexec"/bin/nvcc "$libexec"/bin/cicc "$libexec"/bin/crt "$TOOLKIT/bin/"
  for program in ptxas fatbinary nvlink cudafe++ bin2c nvprune cuobjdump; do
    cp -a "$root/usr/bin/$program" "$TOOLKIT/bin/"
  done
  cp -a "$libexec"/libdevice "$TOOLKIT/nvvm/"
  cp -a "$root"/usr/lib/x86_64-linux-gnu/libnvvm.so* "$TOOLKIT/nvvm/lib64/"
  local site
  site=$("$VENV/bin/python3" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/nvidia
  cp -a "$site"/cuda_runtime/include/. "$site"/cuda_cccl/include/. "$site"/cuda_nvcc/include/. \
    "$TOOLKIT/include/"
  cp -a "$site"/cuda_runtime/lib/. "$TOOLKIT/lib64/"
  ln -sf libcudart.so.11.0 "$TOOLKIT/lib64/libcudart.so"
  cat >"$TOOLKIT/bin/nvcc.profile" <<'EOF'
TOPDIR = $(_HERE_)/..
NVVMIR_LIBRARY_DIR = $(TOPDIR)/nvvm/libdevice
LD_LIBRARY_PATH += $(TOPDIR)/lib64:$(TOPDIR)/nvvm/lib64:
PATH += $(TOPDIR)/nvvm/bin:$(_HERE_):
INCLUDES += "-I$(TOPDIR)/include" $(_SPACE_)
LIBRARIES =+ $(_SPACE_) "-L$(TOPDIR)/lib64"
EOF
  rm -rf "$root"
  touch "$TOOLKIT/.complete"
}

setup() {
  mkdir -p "$CACHE"
  install_debian_packages
  install_python_packages
  download_debian_packages
  unpack_libcxx
  assemble_toolkit
  LD_LIBRARY_PATH=$TOOLKIT/nvvm/lib64 "$TOOLKIT/bin/nvcc" --version | tail -1
  "$CMAKE" --version | head -1
}

# CMake 3.16.3, nvcc 11.8 and g++-11 (nvcc 11's newest host compiler): every CUDA object of the
# library, for both Jetson architectures. Nothing is linked (the PyPI runtime has no static
# libcudart, and no test runs here).
check_cuda() {
  say "CUDA: CMake 3.16.3 + nvcc 11.8 + g++-11 for sm_72 and sm_87"
  export LD_LIBRARY_PATH=$TOOLKIT/nvvm/lib64${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  "$CMAKE" -S . -B "$BUILD/cuda" -DCMAKE_BUILD_TYPE=Release -DCOVOX_BUILD_ROS=OFF \
    -DCOVOX_BUILD_TESTS=OFF -DCOVOX_BUILD_TOOLS=OFF -DCOVOX_WITH_CUDA=ON \
    -DCMAKE_CXX_COMPILER=g++-11 -DCMAKE_CUDA_HOST_COMPILER=g++-11 \
    -DCMAKE_CUDA_COMPILER="$TOOLKIT/bin/nvcc" -DCMAKE_CUDA_FLAGS="-cudart shared" \
    -DCOVOX_CUDA_ARCHITECTURES="$CUDA_ARCHITECTURES" -DCOVOX_THRUST_INCLUDE_DIR="$TOOLKIT/include" \
    >"$BUILD/cuda.configure.log" || { cat "$BUILD/cuda.configure.log"; return 1; }
  local sources
  sources=$(ls cuda/*/*.cu; libstdcxx_extension_sources)
  compile_objects cuda $sources || return 1
  say "CUDA: $(wc -w <<< "$sources") sources compiled for $CUDA_ARCHITECTURES (with the C++ ones that use libstdc++ extensions)"
}

# compile_objects NAME SOURCE...: the library's objects of SOURCE... in $BUILD/NAME (configured
# already), without linking; the first errors of NAME.log on failure. src/<layer>/ and
# cuda/<layer>/ sources belong to the layer's target, covoxslam_<layer>.
compile_objects() {
  local name=$1 source layer
  local -A objects=()
  shift
  for source in "$@"; do
    layer=${source#*/}
    layer=${layer%%/*}
    objects[$layer]+=" CMakeFiles/covoxslam_$layer.dir/$source.o"
  done
  : >"$BUILD/$name.log"
  for layer in "${!objects[@]}"; do
    # shellcheck disable=SC2086  # the object list splits into words
    (cd "$BUILD/$name" && make -j "$JOBS" -f "CMakeFiles/covoxslam_$layer.dir/build.make" ${objects[$layer]}) \
      >>"$BUILD/$name.log" 2>&1 || { show_errors "$BUILD/$name.log"; return 1; }
  done
}

# CMake 3.16.3 and clang 14 against libc++ 14 in C++17 mode: every C++ source of the library.
# Compiled at -O0 into a static library (no link): try_compile checks build static libraries
# too, since libc++ is not installed for linking.
check_cxx() {
  say "C++: CMake 3.16.3 + clang 14 + libc++ 14 (-std=c++17)"
  local flags="-nostdinc++ -isystem $LIBCXX/root/usr/lib/llvm-14/include/c++/v1 -isystem $LIBCXX/omp"
  "$CMAKE" -S . -B "$BUILD/cxx" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG=-O0 \
    -DCOVOX_BUILD_ROS=OFF -DCOVOX_BUILD_TESTS=OFF -DCOVOX_BUILD_TOOLS=OFF -DCOVOX_WITH_CUDA=OFF \
    -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_CXX_FLAGS="$flags" \
    -DCMAKE_TRY_COMPILE_TARGET_TYPE=STATIC_LIBRARY -DCOVOX_THRUST_INCLUDE_DIR="$TOOLKIT/include" \
    >"$BUILD/cxx.configure.log" || { cat "$BUILD/cxx.configure.log"; return 1; }
  local sources
  sources=$(library_cpp_sources | grep -v -x -F -f <(libstdcxx_extension_sources) || true)
  compile_objects cxx $sources || return 1
  say "C++: $(wc -w <<< "$sources") library sources compile against libc++ 14"
}

# The library's C++ sources (the layers cmake/CovoxLayers.cmake globs), and those of them that include a
# libstdc++ extension (<ext/...>, which GCC 9 has and libc++ has not): those compile with g++-11
# in the CUDA step instead.
library_cpp_sources() {
  ls src/{core,map,integrators,backend,io,pipeline}/*.cpp
}
libstdcxx_extension_sources() {
  library_cpp_sources | xargs grep -l '#include <ext/' || true
}

# A compiler's errors (with a few lines of context) from a build log, without the warnings of
# third-party headers that nvcc 11 prints for Eigen 3.4; the whole log stays in the build folder.
show_errors() {
  grep -n -A4 -E "error|Error [0-9]" "$1" | head -80 || true
  say "FAILED; the whole log: $1"
}

# Library features GCC 9.4's libstdc++ lacks that the libc++ 14 compile would let through, in
# every C++ and CUDA source (the ROS layer, tools and tests are not compiled above):
# floating-point std::to_chars (libc++ 14 has it, GCC 11 first), <execution> and
# <memory_resource> (libc++ 14 has neither, so the compile check cannot vouch for them), and
# std::from_chars outside the compiled library (GCC 9 has only its integer overloads; text
# numbers go through covox::parse_double).
check_grep() {
  local sources failed=0 hits
  sources=$(git ls-files '*.h' '*.hpp' '*.cpp' '*.cu' '*.cuh')
  hits=$(grep -n -E 'to_chars *\(|#include <(execution|memory_resource|span|numbers|format|ranges|bit)>' \
    $sources || true)
  if [ -n "$hits" ]; then
    say "not in GCC 9's C++17 library:"; echo "$hits"; failed=1
  fi
  hits=$(grep -n 'from_chars' $(echo "$sources" | grep -v -E '^(src|include)/') || true)
  if [ -n "$hits" ]; then
    say "std::from_chars outside the library (use covox::parse_double for floating point):"
    echo "$hits"; failed=1
  fi
  [ $failed = 0 ] && say "grep: no post-GCC-9 library features"
  return $failed
}

steps=("$@")
[ ${#steps[@]} -gt 0 ] || steps=(setup cuda cxx grep)
start=$(date +%s)
for step in "${steps[@]}"; do
  case $step in
    setup) setup ;;
    cuda) mkdir -p "$BUILD"; check_cuda ;;
    cxx) mkdir -p "$BUILD"; check_cxx ;;
    grep) check_grep ;;
    *) say "unknown step '$step' (steps: setup cuda cxx grep)"; exit 2 ;;
  esac
done
say "passed in $(($(date +%s) - start)) s"
