#!/usr/bin/env bash
# Builds unsup_mvs the way a ROS user does and checks the result: a throw-away catkin workspace
# whose src/unsup_mvs links to this repository, one `catkin_make install`, then
#  * devel space: `rosrun unsup_mvs umvs --help`, and `umvs` on PATH;
#  * install space: `rosrun unsup_mvs umvs --help`, `umvs` on PATH, the four nodes, the nodelet
#    plugin library and nodelet_plugins.xml (found by pluginlib), launch/ config/ models/,
#    `roslaunch --nodes/--files unsup_mvs pipeline.launch` (no master needed), and the generated
#    Python messages (`rosmsg show`, `import unsup_mvs.msg`).
# Only the default target `all` is compiled (umvs, the nodes, the plugin library: the packaged
# things); the test suite is EXCLUDE_FROM_ALL and UMVS_BUILD_TESTS=OFF, so CI does not compile
# the tests a second time. `install` depends on `all`, so a single catkin_make call builds once,
# as a unity build (CMAKE_UNITY_BUILD, as scripts/build.sh): half the time of file by file.
#
#   scripts/check_catkin_workspace.sh [WORKSPACE]
# WORKSPACE defaults to a new folder under ${TMPDIR:-/tmp}, removed afterwards (UMVS_KEEP_WS=1
# keeps it). Not under <repo>/build: rosrun ignores executables below <package>/build/.
# UMVS_JOBS sets the compile jobs (default: all cores). Registered as the ctest `catkin_workspace`.
set -euo pipefail
export PATH=/usr/bin:$PATH  # Debian's ROS Python modules live in /usr/bin/python3
repo=$(cd "$(dirname "$0")/.." && pwd)
jobs=${UMVS_JOBS:-$(nproc)}
if [[ $# -ge 1 ]]; then
  ws=$1
  mkdir -p "$ws"
else
  ws=$(mktemp -d "${TMPDIR:-/tmp}/umvs_catkin_ws.XXXXXX")
  if [[ "${UMVS_KEEP_WS:-0}" != 1 ]]; then trap 'rm -rf "$ws"' EXIT; fi
fi
ws=$(cd "$ws" && pwd)
case "$ws/" in "$repo/build/"*) echo "[check_catkin] $ws is below $repo/build: rosrun would skip it" >&2; exit 2;; esac

fail() { echo "[check_catkin] FAILED: $*" >&2; exit 1; }
# A clean ROS environment: nothing from a sourced devel space (ctest runs us under build's env.sh).
clean_env=(env -i HOME="$HOME" PATH="$PATH" TERM="${TERM:-dumb}" ROS_HOME="$ws/ros_home" LANG=C.UTF-8)

mkdir -p "$ws/src"
ln -sfn "$repo" "$ws/src/unsup_mvs"
start=$SECONDS
echo "[check_catkin] catkin_make install in $ws with $jobs jobs"
"${clean_env[@]}" bash -c "cd '$ws' && catkin_make -j$jobs -DCMAKE_BUILD_TYPE=Release \
  -DCATKIN_ENABLE_TESTING=OFF -DUMVS_BUILD_TESTS=OFF -DCMAKE_UNITY_BUILD=ON -DPYTHON_EXECUTABLE=/usr/bin/python3 \
  install" >"$ws/catkin_make.log" 2>&1 || { tail -n 60 "$ws/catkin_make.log"; fail "catkin_make install"; }
echo "[check_catkin] built and installed in $((SECONDS - start)) s (log: $ws/catkin_make.log)"

# Runs a command in a shell that sourced $1/setup.bash.
in_space() { local space=$1; shift; "${clean_env[@]}" bash -c "source '$space/setup.bash' && $*"; }
expect_umvs_help() {  # the tool's subcommand list, as `umvs --help` (CLI11) prints it
  grep -q "^Usage: umvs \[OPTIONS\] SUBCOMMAND" <<<"$1" && grep -qE "^  infer +depth" <<<"$1"
}

for space in "$ws/devel" "$ws/install"; do
  out=$(in_space "$space" "rosrun unsup_mvs umvs --help" 2>&1) || fail "rosrun unsup_mvs umvs --help ($space): $out"
  expect_umvs_help "$out" || fail "rosrun unsup_mvs umvs --help ($space) printed: $out"
  out=$(in_space "$space" "umvs --help" 2>&1) || fail "umvs --help on PATH ($space): $out"
  expect_umvs_help "$out" || fail "umvs --help ($space) printed: $out"
  echo "[check_catkin] $space: rosrun unsup_mvs umvs and umvs on PATH work"
done

inst=$ws/install
share=$(in_space "$inst" "rospack find unsup_mvs")
[[ "$share" == "$inst/share/unsup_mvs" ]] || fail "rospack find unsup_mvs gave '$share', not the install space"
for node in keyframe_selector_node inference_node fusion_node trainer_node umvs flush_replay.py; do
  [[ -x "$inst/lib/unsup_mvs/$node" ]] || fail "$inst/lib/unsup_mvs/$node missing"
done
[[ -f "$inst/lib/libunsup_mvs_ros.so" ]] || fail "nodelet library $inst/lib/libunsup_mvs_ros.so missing"
for f in nodelet_plugins.xml package.xml launch/pipeline.launch launch/replay.launch config/inference.yaml \
         config/fusion.yaml config/keyframe_selector.yaml config/trainer.yaml models/unsup_mvsnet.pt; do
  [[ -f "$share/$f" ]] || fail "$share/$f missing"
done
plugins=$(in_space "$inst" "rospack plugins --attrib=plugin nodelet")
grep -qx "unsup_mvs $share/nodelet_plugins.xml" <<<"$plugins" || fail "pluginlib does not see $share/nodelet_plugins.xml: $plugins"

nodes=$(in_space "$inst" "roslaunch --nodes unsup_mvs pipeline.launch" 2>&1) || fail "roslaunch --nodes: $nodes"
for n in /unsup_mvs/keyframe_selector /unsup_mvs/inference /unsup_mvs/fusion /unsup_mvs/trainer; do
  grep -qx "$n" <<<"$nodes" || fail "pipeline.launch from the install space lacks $n: $nodes"
done
files=$(in_space "$inst" "roslaunch --files unsup_mvs pipeline.launch" 2>&1) || fail "roslaunch --files: $files"
grep -qx "$share/launch/pipeline.launch" <<<"$files" || fail "roslaunch --files: $files"

out=$(in_space "$inst" "rosmsg show unsup_mvs/TrainingProgress && rossrv show unsup_mvs/SaveCloud && \
  python3 -c 'import unsup_mvs.msg, unsup_mvs.srv; print(unsup_mvs.msg.DepthEstimate._type)'" 2>&1) \
  || fail "generated messages: $out"
grep -q "eta_seconds" <<<"$out" && grep -q "num_points" <<<"$out" && grep -qx "unsup_mvs/DepthEstimate" <<<"$out" \
  || fail "generated messages: $out"
echo "[check_catkin] install space OK ($inst); total $((SECONDS - start)) s"
