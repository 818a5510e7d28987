#!/usr/bin/env bash
# The whole pipeline for an hour, as on a robot: pipeline.launch (keyframe selector, inference with
# the default model, fusion with its occupancy map, the trainer) fed by a camera that never stops
# (scripts/soak_camera.py: a rendered room's log, images at 30 Hz, walked back and forth, keyframes
# as the selector picks them). scripts/soak_monitor.py samples every node's memory and CPU and the
# keyframe sets processed / dropped / failed, and fails when a node dies, a set fails or a node's
# memory keeps growing after the warm-up. Figures: docs/reliability.md.
# Usage: scripts/soak.sh [WORK_DIR]      (default /tmp/umvs_soak; it is replaced)
# Environment: SOAK_MINUTES (60), SOAK_SAMPLE_SECONDS (60), SOAK_WARMUP_MINUTES (10),
#              SOAK_TOLERANCE_MB (32: the smallest memory rise that fails), SOAK_IMAGE_RATE (30 Hz),
#              SOAK_WIDTH x SOAK_HEIGHT (640 x 512: the camera; inference at config/inference.yaml's size),
#              SOAK_VIEWS (24), SOAK_MAX_POINTS (100000: the fused map's cap, which the map reaches in
#              its first minute, so that what the soak watches after warm-up is every node's memory
#              around a full map; empty = the node's default, 2,000,000, reached after hours),
#              SOAK_BUILD (1; 0 = use the build as it is), CHECKPOINT (default model),
#              SOAK_ROS_PORT (11417), UMVS_DEVEL (the build's devel space: build/devel).
# CI runs it for 3 minutes (ctest -R soak).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=$(realpath -m "${1:-/tmp/umvs_soak}")
MINUTES=${SOAK_MINUTES:-60}
SAMPLE=${SOAK_SAMPLE_SECONDS:-60}
WARMUP=${SOAK_WARMUP_MINUTES:-10}
TOLERANCE=${SOAK_TOLERANCE_MB:-32}
RATE=${SOAK_IMAGE_RATE:-30}
WIDTH=${SOAK_WIDTH:-640}
HEIGHT=${SOAK_HEIGHT:-512}
VIEWS=${SOAK_VIEWS:-24}
MAX_POINTS=${SOAK_MAX_POINTS-100000}
CHECKPOINT=$(realpath "${CHECKPOINT:-$ROOT/models/unsup_mvsnet.pt}")
start=$(date +%s)
say() { echo "[soak $(($(date +%s) - start))s] $*"; }

[[ "${SOAK_BUILD:-1}" == 1 ]] && bash scripts/build.sh
export PATH=/usr/bin:$PATH
set +u  # ROS's setup scripts read unset variables
DEVEL=${UMVS_DEVEL:-$ROOT/build/devel}
source "$DEVEL/setup.bash"
set -u
UMVS=$DEVEL/lib/unsup_mvs/umvs

rm -rf "$WORK"
mkdir -p "$WORK"
say "rendering a room ($VIEWS views, ${WIDTH}x$HEIGHT) and its log"
"$UMVS" synth --scene room --seed 7 --views "$VIEWS" --width "$WIDTH" --height "$HEIGHT" --textures none \
  --out "$WORK/scene" >/dev/null
"$UMVS" bag --data "$WORK/scene" --out "$WORK/scene.bag" --rate 2 >/dev/null

export ROS_HOME=$WORK/ros ROS_MASTER_URI=http://localhost:${SOAK_ROS_PORT:-11417}
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done
  for _ in $(seq 20); do
    alive=0
    for p in "${pids[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
    (( alive )) || return 0
    sleep 0.5
  done
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
}
trap cleanup EXIT
cp config/fusion.yaml "$WORK/fusion.yaml"
[[ -n "$MAX_POINTS" ]] && echo "max_points: $MAX_POINTS" >>"$WORK/fusion.yaml"
say "pipeline.launch with $CHECKPOINT, the map capped at ${MAX_POINTS:-the default} points (log: $WORK/launch.log)"
roslaunch -p "${ROS_MASTER_URI##*:}" unsup_mvs pipeline.launch checkpoint:="$CHECKPOINT" clouds_dir:="$WORK/clouds" \
  models_dir:="$WORK/models" fusion_config:="$WORK/fusion.yaml" >"$WORK/launch.log" 2>&1 &
pids+=($!)
until rosservice list 2>/dev/null | grep -q /unsup_mvs/inference/stats; do
  kill -0 "${pids[0]}" 2>/dev/null || { tail -30 "$WORK/launch.log"; echo "pipeline.launch did not start" >&2; exit 1; }
  sleep 1
done
say "the camera: $WORK/scene.bag at $RATE Hz (log: $WORK/camera.log)"
python3 scripts/soak_camera.py "$WORK/scene.bag" "$RATE" >"$WORK/camera.log" 2>&1 &
pids+=($!)
say "watching for $MINUTES min (a sample every $SAMPLE s, warm-up $WARMUP min): $WORK/soak.csv"
status=0
python3 scripts/soak_monitor.py /unsup_mvs "$MINUTES" "$SAMPLE" "$WARMUP" "$WORK/soak.csv" "$TOLERANCE" || status=$?
kill -0 "${pids[1]}" 2>/dev/null || { tail -20 "$WORK/camera.log"; echo "the camera died" >&2; status=1; }
grep -E "inference: keyframe" "$WORK/ros/log/latest/rosout.log" 2>/dev/null | tail -1 | sed -E 's/^.*\[topics: [^]]*\] /  /' || true
say "done"
exit "$status"
