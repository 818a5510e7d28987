#!/usr/bin/env bash
# Builds the portable `umvs` (core + io + tool; no ROS, OpenCV or PCL) against the LibTorch of the
# `python3` on PATH (CUDA or not), with the header-only libraries of `scripts/portable_deps.sh`.
# For a machine without apt (a GPU machine): run portable_deps.sh on a Debian machine first and
# copy its folder along. The tool is then BUILD_DIR/devel/lib/unsup_mvs/umvs.
#
# Usage: scripts/build_portable.sh [BUILD_DIR]           (default: build-portable)
#   environment: UMVS_DEPS (.portable_deps), TORCH_PREFIX (default: python3's torch.utils.cmake_prefix_path),
#                UMVS_OPENMP (ON; OFF if the compiler's OpenMP and the LibTorch's do not mix), JOBS (nproc)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build-portable}"
DEPS="$(cd "${UMVS_DEPS:-.portable_deps}" 2>/dev/null && pwd)" ||
  { echo "build_portable: no ${UMVS_DEPS:-.portable_deps}: run scripts/portable_deps.sh on a Debian machine" >&2; exit 1; }
if [ -z "${TORCH_PREFIX:-}" ]; then
  TORCH_PREFIX="$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)' 2>/dev/null)" ||
    { echo "build_portable: python3 has no torch: set TORCH_PREFIX to a LibTorch's cmake folder" >&2; exit 1; }
fi
echo "[build_portable] LibTorch from $TORCH_PREFIX, headers from $DEPS"
mkdir -p "$BUILD_DIR"
CONFIGURE_LOG="$BUILD_DIR/cmake.log"  # inside the folder: any spelling of BUILD_DIR works (a trailing /)
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DUMVS_WITH_ROS=OFF -DUMVS_WITH_OPENCV=OFF \
  -DUMVS_BUILD_TESTS=OFF -DUMVS_OPENMP="${UMVS_OPENMP:-ON}" \
  -DCMAKE_PREFIX_PATH="$TORCH_PREFIX;$DEPS" -DCMAKE_CXX_FLAGS="-isystem $DEPS/include" \
  >"$CONFIGURE_LOG" 2>&1 || { cat "$CONFIGURE_LOG"; exit 1; }
cmake --build "$BUILD_DIR" -j"${JOBS:-$(nproc)}" --target umvs
echo "[build_portable] done: $BUILD_DIR/devel/lib/unsup_mvs/umvs"
