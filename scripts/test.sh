#!/usr/bin/env bash
# Installs what is missing, builds everything (all + tests) and runs every gtest and rostest
# through ctest. Exits non-zero on any failure. Tests that need ../shared/data skip with a
# message when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh --target all tests
export PATH=/usr/bin:$PATH
BUILD_DIR=${UMVS_BUILD_DIR:-build}
# rostest writes logs under ROS_HOME; keep them inside the build folder.
export ROS_HOME="$PWD/$BUILD_DIR/ros_home"
mkdir -p "$ROS_HOME"
cd "$BUILD_DIR"
ctest --output-on-failure --timeout 1200 "${@}"
