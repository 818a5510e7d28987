#!/usr/bin/env bash
# Installs everything unsup_mvs needs from Debian 12's apt. Idempotent: when every package is
# already installed it returns in about a second without touching apt.
#   scripts/install_deps.sh          build + test dependencies
#   scripts/install_deps.sh --viz    also RViz, Xvfb and netpbm (headless screenshots, desktop use)
set -euo pipefail

PACKAGES=(
  # toolchain and libraries of the core
  build-essential cmake pkg-config git
  libtorch-dev libopenblas0-pthread libeigen3-dev libnanoflann-dev
  libgloo-dev  # headers of the c10d Gloo backend in libtorch (data-parallel umvs train)
  libgtest-dev libgmock-dev
  libstb-dev  # image codecs for the portable build without OpenCV
  # io
  libopencv-dev
  # ROS 1 (Debian's packaging): build system, message generation and definitions
  catkin ros-cmake-modules ros-message-generation ros-message-runtime
  python3-catkin-pkg python3-genmsg python3-gencpp python3-genpy python3-empy
  ros-std-msgs libstd-msgs-dev ros-sensor-msgs libsensor-msgs-dev
  ros-geometry-msgs libgeometry-msgs-dev ros-diagnostic-msgs libdiagnostic-msgs-dev
  ros-nav-msgs libnav-msgs-dev python3-nav-msgs ros-map-msgs libmap-msgs-dev python3-map-msgs
  ros-std-srvs libstd-srvs-dev ros-tf2-msgs libtf2-msgs-dev ros-rosgraph-msgs
  # ROS 1 libraries the nodes use
  libroscpp-dev libnodeletlib-dev libnodelet-dev pluginlib-dev
  libtf2-dev libtf2-ros-dev libtf2-eigen-dev
  libimage-transport-dev libmessage-filters-dev
  librosbag-dev librosbag-storage-dev
  libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure  # live tuning
  # PCL at the edge (clouds published as pcl::PointCloud, .pcd files, outlier removal)
  libpcl-dev libpcl-conversions-dev libpcl-ros-dev
  # libraries instead of hand-written parts: command line, JSON
  libcli11-dev nlohmann-json3-dev
  # Python message classes, so `rostopic echo` / `rosservice call` work on our topics and services
  python3-std-msgs python3-sensor-msgs python3-geometry-msgs python3-diagnostic-msgs
  python3-std-srvs python3-rosgraph-msgs python3-tf2-msgs
  # ROS 1 runtime tools: master, roslaunch, rostest, rosbag play
  ros-core python3-rostest librostest-dev rosbash
  python3-numpy  # test/ros/test_ros_tools.py
  # the `nodelet` executable (manager / load) that launch/pipeline.launch runs
  libnodeletlib-tools
  # occupancy maps (OctoMap) and its command-line tools
  liboctomap-dev octomap-tools
  # depth_image_proc's nodelets: the rostest hands our depth camera (REP 118) to point_cloud_xyz
  libdepth-image-proc-dev
)
if [[ "${1:-}" == "--viz" ]]; then
  PACKAGES+=(rviz xvfb netpbm)  # netpbm: Xvfb framebuffer (XWD) -> PNG
fi

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
  echo "[install_deps] all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
echo "[install_deps] installing ${#missing[@]} missing packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
echo "[install_deps] done"
