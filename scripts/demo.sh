#!/usr/bin/env bash
# From a fresh Debian 12 machine to a fused point cloud, in one command:
#   1. installs the dependencies (apt, incl. RViz + Xvfb for a headless screenshot) and builds,
#   2. renders a synthetic room with exact geometry (`umvs synth`) and logs it as a robot would
#      (`umvs bag`: Image + CameraInfo + /tf),
#   3. replays the bag through the ROS pipeline (replay.launch: keyframe selector -> inference with
#      the default model models/unsup_mvsnet.pt -> fusion) with RViz on a virtual display,
#   4. at the end of the log sends the last keyframe too (keyframe_selector's flush service,
#      scripts/flush_replay.py), saves the fused cloud (fusion's save_cloud service), takes an
#      RViz screenshot, and prints `umvs eval cloud` against the scene's ground-truth surface and
#      the keyframe sets processed and dropped with their p50/p90 times (inference's ~stats).
# Usage: scripts/demo.sh [WORK_DIR]      (default /tmp/umvs_demo; it is replaced)
# Environment: DEMO_SCENE (room), DEMO_SEED (7), DEMO_VIEWS (24), DEMO_WIDTH x DEMO_HEIGHT (640 x 512,
#              the default model's training size; images and inference), DEMO_PLANES, DEMO_FINE_PLANES,
#              DEMO_FIRST_PASS_DOWNSCALE, DEMO_FINE_RESOLUTION (empty: config/inference.yaml's planes and passes),
#              DEMO_RATE (playback factor, 0.25: slow enough for a 2-core CPU to infer every
#              keyframe at that size), DEMO_RVIZ (1; 0 = no RViz, no screenshot), CHECKPOINT (default model),
#              DEMO_TEXTURES (none: procedural textures, the same scene on every machine; `installed`
#              after scripts/install_textures.sh renders photographs, a different scene with other scores),
#              DEMO_COMPLETION (empty: inference_config's, 0.7; 0 = off: the inference nodelet's
#              ~complete_below_confidence, docs/ros.md).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=$(realpath -m "${1:-/tmp/umvs_demo}")
SCENE=${DEMO_SCENE:-room}
SEED=${DEMO_SEED:-7}
VIEWS=${DEMO_VIEWS:-24}
WIDTH=${DEMO_WIDTH:-640}
HEIGHT=${DEMO_HEIGHT:-512}
PLANES=${DEMO_PLANES:-}
FINE_PLANES=${DEMO_FINE_PLANES:-}
FIRST_PASS_DOWNSCALE=${DEMO_FIRST_PASS_DOWNSCALE:-}
FINE_RESOLUTION=${DEMO_FINE_RESOLUTION:-}
RATE=${DEMO_RATE:-0.25}
RVIZ=${DEMO_RVIZ:-1}
TEXTURES=${DEMO_TEXTURES:-none}
COMPLETION=${DEMO_COMPLETION:-}
CHECKPOINT=$(realpath "${CHECKPOINT:-$ROOT/models/unsup_mvsnet.pt}")
start=$(date +%s)
say() { echo "[demo $(($(date +%s) - start))s] $*"; }

deps=""
[[ "$RVIZ" == 1 ]] && deps="--viz"
UMVS_DEPS_ARGS=$deps bash scripts/build.sh
export PATH=/usr/bin:$PATH
set +u  # ROS's setup scripts read unset variables
source build/devel/setup.bash
set -u
UMVS=$ROOT/build/devel/lib/unsup_mvs/umvs

rm -rf "$WORK"
mkdir -p "$WORK"
say "rendering a synthetic $SCENE ($VIEWS views, ${WIDTH}x$HEIGHT) with ground truth into $WORK/scene"
"$UMVS" synth --scene "$SCENE" --seed "$SEED" --views "$VIEWS" --width "$WIDTH" --height "$HEIGHT" --textures "$TEXTURES" \
  --out "$WORK/scene" >/dev/null
"$UMVS" bag --data "$WORK/scene" --out "$WORK/scene.bag" --rate 2 >/dev/null
"$UMVS" bag --inspect "$WORK/scene.bag"

# Own ROS master and log folder; everything started here is stopped on exit.
export ROS_HOME=$WORK/ros ROS_MASTER_URI=http://localhost:${DEMO_ROS_PORT:-11411}
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done
  sleep 2
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
}
trap cleanup EXIT
if [[ "$RVIZ" == 1 ]]; then
  mkdir -p "$WORK/xvfb"
  display=:$((90 + RANDOM % 100))
  Xvfb "$display" -screen 0 1280x800x24 -fbdir "$WORK/xvfb" -nolisten tcp >"$WORK/xvfb.log" 2>&1 &
  pids+=($!)
  export DISPLAY=$display
fi
say "replaying at ${RATE}x through replay.launch with $CHECKPOINT, inference at ${WIDTH}x$HEIGHT (planes and passes: ${PLANES:-from config/inference.yaml}; log: $WORK/launch.log)"
roslaunch -p "${ROS_MASTER_URI##*:}" unsup_mvs replay.launch bag:="$WORK/scene.bag" checkpoint:="$CHECKPOINT" clouds_dir:="$WORK" \
  max_width:="$WIDTH" max_height:="$HEIGHT" num_depth:="$PLANES" fine_planes:="$FINE_PLANES" \
  first_pass_downscale:="$FIRST_PASS_DOWNSCALE" fine_resolution:="$FINE_RESOLUTION" rate:="$RATE" rviz:=$([[ "$RVIZ" == 1 ]] && echo true || echo false) trainer:=false \
  complete_below_confidence:="$COMPLETION" >"$WORK/launch.log" 2>&1 &
pids+=($!)

# roslaunch logs the player's exit when the bag is done (polling the master is unreliable under load).
player_done() { grep -Eq '\[player-[0-9]+\] process has (finished|died)' "$WORK/launch.log"; }
limit=$(( $(date +%s) + 120 + VIEWS * 2 ))
until player_done; do
  if (( $(date +%s) > limit )) || ! kill -0 "${pids[-1]}" 2>/dev/null; then
    tail -30 "$WORK/launch.log"; echo "the replay did not finish" >&2; exit 1
  fi
  sleep 1
done
sleep 8  # the last keyframe sets through inference and fusion
say "bag done; the keyframe still waiting for a newer one goes out too (keyframe_selector/flush)"
python3 scripts/flush_replay.py /unsup_mvs 120
# Every set the selector sent, processed or dropped, and how long each took (the inference nodelet's ~stats).
stats=$(python3 -c "import rospy; from std_srvs.srv import Trigger
print(rospy.ServiceProxy('/unsup_mvs/inference/stats', Trigger)().message)" 2>/dev/null || true)
say "saving the fused cloud"
rosservice call /unsup_mvs/fusion/save_cloud "path: '$WORK/cloud.ply'"
# The nodes' last words (rosout.log: "stamp LEVEL node [file] [topics: ...] message").
grep -E "inference: keyframe|fusion: depth estimate" "$WORK/ros/log/latest/rosout.log" 2>/dev/null | tail -2 |
  sed -E 's/^.*\[topics: [^]]*\] /  /' || true
shot=""
if [[ "$RVIZ" == 1 ]] && xwdtopnm "$WORK/xvfb/Xvfb_screen0" 2>/dev/null | pnmtopng >"$WORK/rviz.png" 2>/dev/null; then
  shot=$WORK/rviz.png
fi

echo
"$UMVS" eval cloud --est "$WORK/cloud.ply" --gt "$WORK/scene/gt.ply" --thresholds 0.02,0.05,0.1 | tee "$WORK/eval.txt"
echo
say "done"
echo "inference:        ${stats:-(no answer from /unsup_mvs/inference/stats)}"
echo "fused cloud:      $WORK/cloud.ply"
echo "ground truth:     $WORK/scene/gt.ply"
echo "RViz screenshot:  ${shot:-(not taken: run with DEMO_RVIZ=1 and rviz/xvfb/netpbm installed)}"
echo "view it:          roslaunch unsup_mvs replay.launch bag:=$WORK/scene.bag checkpoint:=$CHECKPOINT rviz:=true"
