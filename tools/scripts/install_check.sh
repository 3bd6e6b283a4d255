#!/usr/bin/env bash
# Checks an installed covoxslam the way its users meet it, from the install space alone (no
# source tree, no devel space on any search path):
#   * ROS: rospack finds the package in the prefix; nodelet's plugin list names its
#     nodelet_plugins.xml there; roslaunch resolves arche.launch to the installed node, nodelet
#     library, configuration and rviz file; the nodelet rostest runs from the install space;
#   * CMake: test/downstream, a separate project, finds the installed package, links
#     covox::covoxslam, and its program maps a small scene.
#
#   tools/scripts/install_check.sh PREFIX [BUILD_DIR]
#
# PREFIX is an install space made with -DCOVOX_INSTALL_TESTS=ON (the rostest node and test
# files); `make install-check` makes one and runs this. The downstream project builds in
# BUILD_DIR/downstream (default build).
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
PREFIX=$(cd "${1:?usage: $0 PREFIX [BUILD_DIR]}" && pwd)
DOWNSTREAM_BUILD=${2:-build}/downstream
SHARE=$PREFIX/share/covoxslam

say() { echo "install-check: $*"; }
fail() { echo "install-check: FAILED: $*" >&2; exit 1; }
# Fails naming `what` unless `text` contains `expected`.
expect_in() {
  local what=$1 text=$2 expected=$3
  grep -qF -- "$expected" <<<"$text" || { echo "$text" >&2; fail "$what does not name $expected"; }
}

unset ROS_PACKAGE_PATH CMAKE_PREFIX_PATH LD_LIBRARY_PATH PYTHONPATH PKG_CONFIG_PATH
set +u
# shellcheck disable=SC1091
source "$PREFIX/setup.bash"
set -u

found=$(rospack find covoxslam)
[ "$found" = "$SHARE" ] || fail "rospack finds covoxslam at $found, not in the install space $SHARE"
expect_in "nodelet's plugin list" "$(rospack plugins --attrib=plugin nodelet)" \
  "covoxslam $SHARE/nodelet_plugins.xml"
[ -f "$PREFIX/lib/libcovoxslam_ros.so" ] || fail "no nodelet library $PREFIX/lib/libcovoxslam_ros.so"
say "rospack and nodelet find the package and its plugin in $PREFIX"

nodes=$(roslaunch --nodes covoxslam arche.launch rviz:=true)
for node in /covoxslam_manager /covoxslam /covoxslam_rviz; do expect_in "roslaunch --nodes" "$nodes" "$node"; done
expect_in "the rviz node's arguments" "$(roslaunch --args /covoxslam_rviz covoxslam arche.launch rviz:=true)" \
  "$SHARE/rviz/covoxslam.rviz"
[ -f "$SHARE/rviz/covoxslam.rviz" ] || fail "no $SHARE/rviz/covoxslam.rviz"
expect_in "the node's command line" \
  "$(roslaunch --args /covoxslam covoxslam arche.launch use_nodelet:=false)" \
  "$PREFIX/lib/covoxslam/covoxslam_node"
expect_in "the configuration files" "$(roslaunch --files covoxslam arche.launch)" "$SHARE/launch/covoxslam.launch"
[ -f "$SHARE/config/arche.yaml" ] || fail "no $SHARE/config/arche.yaml"
say "roslaunch resolves arche.launch to the installed node, configuration and rviz file"

rostest covoxslam covoxslam_nodelet.test
say "the nodelet rostest passes from the install space"

cmake -S test/downstream -B "$DOWNSTREAM_BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$DOWNSTREAM_BUILD" -j "$(nproc)"
"$DOWNSTREAM_BUILD/covox_downstream_tsdf"
say "a downstream CMake project finds, links and runs covox::covoxslam"
