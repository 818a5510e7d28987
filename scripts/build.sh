#!/usr/bin/env bash
# Installs missing Debian packages, configures and builds unsup_mvs into build/ (devel space
# build/devel; the tool is build/devel/lib/unsup_mvs/umvs). Extra arguments go to `cmake --build`
# (e.g. `--target tests`). UMVS_BUILD_DIR overrides the build folder. UMVS_UNITY_BUILD (ON) compiles
# the sources in batches (CMake's unity build: a fresh build takes half the time; set OFF when
# rebuilding often after small edits, where a batch recompiles for one file).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh "${UMVS_DEPS_ARGS:-}"
# Debian's ROS Python modules live in /usr/bin/python3; a pyenv python3 earlier on PATH has none.
export PATH=/usr/bin:$PATH
BUILD_DIR=${UMVS_BUILD_DIR:-build}
mkdir -p "$BUILD_DIR"
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DCATKIN_ENABLE_TESTING=ON \
  -DCMAKE_UNITY_BUILD="${UMVS_UNITY_BUILD:-ON}" \
  -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 >"$BUILD_DIR/cmake.log" 2>&1 \
  || { cat "$BUILD_DIR/cmake.log"; exit 1; }
echo "[build] configured $BUILD_DIR (log: $BUILD_DIR/cmake.log); compiling with $(nproc) jobs"
cmake --build "$BUILD_DIR" -j"$(nproc)" "$@"
echo "[build] done: $BUILD_DIR/devel/lib/unsup_mvs/umvs"
