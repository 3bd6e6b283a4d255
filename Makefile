# covoxslam: the two commands of the README, and the steps they are made of.
#
#   make demo   installs what is missing (the build packages only: no ROS, no test libraries),
#               builds the three programs it runs in its own folder (build_demo: no ROS layer, no
#               tests; CUDA only when a GPU is usable), simulates the default drone flight (cached
#               after the first run) and maps it, GPU if present, CPU otherwise
#   make test   installs what is missing, builds everything (library, tools, tests, ROS layer)
#               and runs the whole test suite
#   make ros    installs what is missing (ROS 1, rviz, the message and tf command-line tools) and
#               builds the ROS layer (nodelet, node, messages) into BUILD_DIR; then
#               `source build/devel/setup.bash` makes roslaunch / rosrun / rostopic find it
#   make toolchain-check   compiles the library with a JetPack 5 robot's toolchain without one:
#               CMake 3.16.3, nvcc 11.8 for sm_72/sm_87, libc++ 14 in C++17 mode
#               (tools/scripts/toolchain_check.sh; downloads cached in ~/.cache/covoxslam-toolchain)
#   make limits-check   no function over cyclomatic complexity 20 or 100 lines, no file-header
#               comment over 10 lines (tools/scripts/check_code_limits.sh)
#   make install-check     installs BUILD_DIR into INSTALL_PREFIX (default install/) and checks
#               it as a user would: roslaunch, nodelet, rostest, a downstream CMake project
#               (tools/scripts/install_check.sh)
#
# Settings (make VAR=value):
#   CUDA_ARCH   CUDA architectures to compile for. Default: 90 (one architecture, because nvcc on
#               a 2-core machine is slow); `make release` keeps the full Jetson + desktop list.
#   WITH_CUDA   ON (default when nvcc exists) or OFF: the CPU backend is always built.
#   BUILD_DIR   build folder of make build / make test (default build)
#   DEMO_BUILD_DIR  build folder of make demo (default build_demo)
#   DEMO_WITH_CUDA  ON or OFF for the demo (default ON only when `nvidia-smi -L` lists a GPU and
#               nvcc exists: without a GPU the CUDA backend would only cost nvcc time)
#   JOBS        parallel compile jobs (default: number of cores)
#   COVOX_DATA_DIR  the shared real sensor data (default ../shared/data)
SHELL := /bin/bash

# A pyenv/conda python3 ahead of /usr/bin breaks catkin's Python modules: Debian's come first.
export PATH := /usr/bin:/bin:/usr/sbin:/sbin:/usr/local/cuda/bin:$(PATH)

BUILD_DIR ?= build
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
CUDA_ARCH ?= 90
WITH_CUDA ?= $(if $(wildcard /usr/local/cuda/bin/nvcc),ON,OFF)
COVOX_DATA_DIR ?= $(abspath $(CURDIR)/../shared/data)
export COVOX_DATA_DIR

# Thrust's headers come with the CUDA toolkit (CCCL); without it, Debian's libthrust-dev.
THRUST_PACKAGE := $(if $(wildcard /usr/local/cuda/include/cccl/thrust/version.h /usr/local/cuda/include/thrust/version.h),,libthrust-dev)
# Debian 12 packages: what the demo's programs need (liblz4 and libbz2: run_slam reads bags
# recorded with --lz4 or --bz2), then the library's optional readers and the tests, then the ROS 1
# layer (Debian's own ROS packages).
DEBIAN_DEMO_PACKAGES := cmake make g++ libeigen3-dev $(THRUST_PACKAGE) liblz4-dev libbz2-dev
DEBIAN_BUILD_PACKAGES := $(DEBIAN_DEMO_PACKAGES) pkg-config libgtest-dev libpng-dev \
  libjpeg-dev zlib1g-dev libceres-dev
DEBIAN_ROS_PACKAGES := catkin ros-core-dev libroscpp-dev libnodeletlib-dev libnodelet-dev \
  libtf2-ros-dev libtf2-eigen-dev libpcl-dev libpcl-conversions-dev librosbag-dev pluginlib-dev \
  libsensor-msgs-dev libnav-msgs-dev libvisualization-msgs-dev libgeometry-msgs-dev \
  libstd-srvs-dev ros-message-generation librostest-dev python3-rostest libnodeletlib-tools rosbash \
  python3-rosbag python3-roslaunch libmessage-filters-dev libdiagnostic-msgs-dev \
  libdiagnostic-updater-dev libtf2-dev \
  python3-std-srvs python3-diagnostic-msgs
# What the documented ROS commands run: rviz, rostopic / rosservice / rosnode with the Python
# message packages of the node's inputs and outputs, and the tf tools (tf_echo, view_frames).
DEBIAN_ROS_TOOL_PACKAGES := rviz python3-rostopic python3-rosservice python3-rosnode \
  python3-std-msgs python3-geometry-msgs python3-sensor-msgs python3-nav-msgs \
  python3-visualization-msgs python3-tf2-msgs python3-tf2-ros tf-tools tf2-tools
DEBIAN_PACKAGES := $(DEBIAN_BUILD_PACKAGES) $(DEBIAN_ROS_PACKAGES) $(DEBIAN_ROS_TOOL_PACKAGES)

CMAKE_FLAGS := -DCMAKE_BUILD_TYPE=Release -DCOVOX_WITH_CUDA=$(WITH_CUDA) \
  -DCOVOX_CUDA_ARCHITECTURES="$(CUDA_ARCH)" -DCOVOX_DATA_DIR="$(COVOX_DATA_DIR)"

DEMO_DIR ?= demo_output
DEMO_BUILD_DIR ?= build_demo
GPU_USABLE := $(shell nvidia-smi -L 2>/dev/null | grep -q '^GPU' && echo yes)
DEMO_WITH_CUDA ?= $(if $(and $(GPU_USABLE),$(wildcard /usr/local/cuda/bin/nvcc)),ON,OFF)
DEMO_CMAKE_FLAGS := -DCMAKE_BUILD_TYPE=Release -DCOVOX_WITH_CUDA=$(DEMO_WITH_CUDA) \
  -DCOVOX_CUDA_ARCHITECTURES="$(CUDA_ARCH)" -DCOVOX_BUILD_ROS=OFF -DCOVOX_BUILD_TESTS=OFF

DEMO_TARGETS := simulate_flight run_slam evaluate_trajectory

.PHONY: all deps demo-deps configure build test demo ros release clean format format-check \
  limits-check toolchain-check install-check layer-check

all: build

# Installs only what is missing, so a second run costs a second, not an apt-get update.
# $(1): the package list.
define install_missing
	@missing=$$(for p in $(1); do \
	    dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q 'install ok installed' || echo $$p; \
	  done); \
	if [ -n "$$missing" ]; then \
	  echo "covoxslam: installing Debian packages:" $$missing; \
	  if [ "$$(id -u)" != 0 ]; then SUDO=sudo; fi; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	else echo "covoxslam: all Debian packages present"; fi
endef

deps:
	$(call install_missing,$(DEBIAN_PACKAGES))

demo-deps:
	$(call install_missing,$(DEBIAN_DEMO_PACKAGES))

# Configuring again is cheap and picks up changed settings (CUDA_ARCH, WITH_CUDA).
configure: deps
	cmake -S . -B $(BUILD_DIR) $(CMAKE_FLAGS)

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) --timeout 600

# Builds only the programs the demo runs, in the demo's own folder, without the ROS layer and the
# tests (those are `make test`'s business; sharing its folder would flip its settings).
demo: demo-deps
	cmake -S . -B $(DEMO_BUILD_DIR) $(DEMO_CMAKE_FLAGS)
	cmake --build $(DEMO_BUILD_DIR) -j $(JOBS) --target $(DEMO_TARGETS)
	tools/run_demo.sh $(DEMO_BUILD_DIR) $(DEMO_DIR)

# The ROS layer alone (and the library under it), for roslaunch: the nodelet library, the node and
# the messages (C++ and Python) in $(BUILD_DIR)/devel.
ROS_TARGETS := covoxslam_ros covoxslam_node covoxslam_generate_messages

# grep reads the whole target list (no -q): quitting at the first match would close the pipe on
# cmake, which then reports "execution of make failed".
ros: configure
	@cmake --build $(BUILD_DIR) --target help | grep covoxslam_ros >/dev/null || \
	  { echo "covoxslam: the ROS layer is not configured (see CMake's warning above)"; exit 1; }
	cmake --build $(BUILD_DIR) -j $(JOBS) --target $(ROS_TARGETS)
	@echo "covoxslam: ROS layer built; in each new shell: source $(BUILD_DIR)/devel/setup.bash"

toolchain-check:
	tools/scripts/toolchain_check.sh

# The install space of BUILD_DIR's configuration, with the rostest node and its test files.
INSTALL_PREFIX ?= $(CURDIR)/install

install-check: deps
	cmake -S . -B $(BUILD_DIR) $(CMAKE_FLAGS) -DCMAKE_INSTALL_PREFIX="$(INSTALL_PREFIX)" \
	  -DCOVOX_INSTALL_TESTS=ON
	cmake --build $(BUILD_DIR) -j $(JOBS) --target install
	tools/scripts/install_check.sh "$(INSTALL_PREFIX)" "$(BUILD_DIR)"

# What a release builds: every supported CUDA architecture.
release:
	$(MAKE) build BUILD_DIR=build_release CUDA_ARCH="75;80;86;87;89;90"

clean:
	rm -rf $(BUILD_DIR) $(DEMO_BUILD_DIR)

# Every C++ and CUDA source in the repository, formatted by .clang-format (Debian's clang-format).
FORMAT_SOURCES = $(shell git ls-files '*.h' '*.hpp' '*.cpp' '*.cu' '*.cuh')

format:
	$(call install_missing,clang-format)
	clang-format -i $(FORMAT_SOURCES)

# Fails, naming the files, when a source differs from what `make format` would write.
format-check:
	$(call install_missing,clang-format)
	clang-format --dry-run --Werror $(FORMAT_SOURCES)

# Fails, naming the file, the include and the rule, when a library source includes a header of a
# layer it may not use (the table in cmake/CovoxLayerTable.cmake, which the script reads with
# cmake -P; docs/design.md, "Layers").
layer-check:
	$(call install_missing,cmake)
	tools/scripts/check_layers.sh

# Fails, naming each offender, when a function outside the tests passes cyclomatic complexity 20
# or 100 lines (lizard, installed into ~/.cache) or a file-header comment in include/, src/ or
# cuda/ passes 10 lines; the exceptions, each with its reason, are in
# tools/scripts/complexity_exceptions.txt.
limits-check:
	bash tools/scripts/check_code_limits.sh
