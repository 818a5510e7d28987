#!/usr/bin/env bash
# Trains the default model models/unsup_mvsnet.pt with no real label:
#   * rendered scenes (`scripts/experiments/render_training_scenes.sh`: objects on a table, furnished rooms,
#     corridors and streets wearing photographs, object-scan and robot camera paths, lighting
#     changes, specular and textureless patches) are supervised on their exact depth (smooth L1 in
#     depth intervals, MVSNet's loss);
#   * real, unlabeled images (Middlebury templeRing, when ../shared/data/templeRing exists) train
#     with the robust photometric loss (paper weights) in the same optimisation;
#   * inputs are normalised per image and channel, and tuples are darkened/brightened by a random
#     exposure gain, so that a dark or low-contrast camera gives the same depth;
#   * planes are spaced in inverse depth (robot scenes span 0.3-30 m).
# Held-out rendered scenes (other seeds) are validated on; the model is last.pt (no label of the
# real data picks it). Writes WORK/run/{last.pt,best.pt,train_log.csv,loss_curve.png}; rerunning
# resumes from WORK/run/last.pt.
#
# Usage: scripts/experiments/train_default_model.sh [WORK_DIR]
#   environment: UMVS, STEPS (6000), THREADS (2), SEED (1), SCENES_PER_RECIPE (8), TEXTURES
#   (installed | DIR[,DIR] | none), DEVICE (cpu | cuda), WIDTH x HEIGHT, NUM_DEPTH (160 x 128, 32),
#   BATCH (1), INIT (start from this checkpoint instead of random weights), MAX_MINUTES (0: none),
#   NETWORK (mvsnet | sweep2d: the network of a new model; sweep2d defaults to 320 x 256 and 64
#   planes), REAL_VIDEOS ("" | "hololens tum": those real videos' frames and poses trained on with
#   the photometric loss, imported with a fixed 0.3-8 m range and without their depth; 7-Scenes is
#   never trained on; REAL_VIDEO_FRAMES: the first N frames of each, 0 = all), RENDER_JOBS (scenes rendered at once, 1), LR (1e-3), LR_SCHEDULE (constant | cosine), LR_MIN (0),
#   FEATURE_WARP (exact; mvsnet_pytorch only to reproduce models trained before the warp was fixed),
#   RENDER_WIDTH x RENDER_HEIGHT (320 x 256: the rendered scenes' size), SUPERVISED_SHARE (0.75: the
#   share of tuples from rendered scenes; the rest are templeRing's, photometric), MIN_ZOOM and
#   MAX_ZOOM (1 and 1.25: the random crop's zoom; RENDER_WIDTH / WIDTH trains on crops at the
#   renders' own pixel scale, `umvs train --min-zoom`)
#
# The shipped model is three runs of this script, each from the one before (models/README.md has
# each run's data, steps and commands; TEXTURES as installed by install_textures.sh):
#   1. CPU:  defaults (160x128, D = 32, 6,000 steps, constant 1e-3, random weights), run with the
#            script as it was at commit 89ba1aa (24 scenes, no corridors);
#   2. GPU:  DEVICE=cuda WIDTH=320 HEIGHT=256 NUM_DEPTH=64 INIT=<1> STEPS=100000 MAX_MINUTES=4.7
#            (stopped by time at step 3,761),
#            FEATURE_WARP=mvsnet_pytorch (the warp of its day), then switched to the exact warp
#            (umvs train --init <2> --feature-warp exact --steps 0);
#   3. GPU:  DEVICE=cuda WIDTH=640 HEIGHT=512 NUM_DEPTH=128 RENDER_WIDTH=640 RENDER_HEIGHT=512
#            SUPERVISED_SHARE=0.5 LR=5e-4 LR_SCHEDULE=cosine STEPS=2629 MAX_MINUTES=5.27 INIT=<2>
#            (stopped by time at step 2,357), weights exported with --steps 0.
# A fourth, CPU run on crops at the renders' own scale (WIDTH=320 HEIGHT=256 NUM_DEPTH=128
# RENDER_WIDTH=640 RENDER_HEIGHT=512 MIN_ZOOM=2 MAX_ZOOM=2.5 SCENES_PER_RECIPE=16
# SUPERVISED_SHARE=0.5 LR=2e-4 LR_SCHEDULE=cosine STEPS=2400 THREADS=2 INIT=<3>, 52 minutes on
# 2 cores) is better before adaptation but not shipped (docs/experiments.md).
# A fifth, GPU run from <3> (run 3's settings, SCENES_PER_RECIPE=10, LR=5e-4 or 2e-4, STEPS=1923)
# gains on rendered scenes and loses on real images: not shipped (docs/experiments.md).
# On a GPU machine without apt, build UMVS with scripts/build_portable.sh and pass the textures of
# scripts/portable_deps.sh --textures (docs/building.md).
set -euo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
WORK="${1:-/tmp/umvs_default_model}"
STEPS="${STEPS:-6000}"
THREADS="${THREADS:-2}"
SEED="${SEED:-1}"
SCENES_PER_RECIPE="${SCENES_PER_RECIPE:-8}"
TEXTURES="${TEXTURES:-installed}"
DEVICE="${DEVICE:-cpu}"
NETWORK="${NETWORK:-mvsnet}"
REAL_VIDEOS="${REAL_VIDEOS:-}"
REAL_VIDEO_FRAMES="${REAL_VIDEO_FRAMES:-0}"
if [ "$NETWORK" = sweep2d ]; then
  WIDTH="${WIDTH:-320}"
  HEIGHT="${HEIGHT:-256}"
  NUM_DEPTH="${NUM_DEPTH:-64}"
fi
WIDTH="${WIDTH:-160}"
HEIGHT="${HEIGHT:-128}"
NUM_DEPTH="${NUM_DEPTH:-32}"
BATCH="${BATCH:-1}"
INIT="${INIT:-}"
MAX_MINUTES="${MAX_MINUTES:-0}"
LR="${LR:-1e-3}"
LR_SCHEDULE="${LR_SCHEDULE:-constant}"
LR_MIN="${LR_MIN:-0}"
FEATURE_WARP="${FEATURE_WARP:-exact}"
RENDER_WIDTH="${RENDER_WIDTH:-320}"
RENDER_HEIGHT="${RENDER_HEIGHT:-256}"
SUPERVISED_SHARE="${SUPERVISED_SHARE:-0.75}"
MIN_ZOOM="${MIN_ZOOM:-1}"
MAX_ZOOM="${MAX_ZOOM:-1.25}"

require_umvs
mkdir -p "$WORK/data"
# glibc keeps freed tensor buffers instead of unmapping them (no page faults on every step) and
# BLAS does not spin threads next to LibTorch's: 2-3x faster steps on a busy 2-core machine.
export MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=4294967296 MALLOC_TOP_PAD_=268435456
export OPENBLAS_NUM_THREADS=1

# Training scenes (seeds 1000..) and held-out scenes (seeds 5000.., never trained on), rendered at
# RENDER_WIDTH x RENDER_HEIGHT; training zooms, crops and scales them to WIDTH x HEIGHT.
RENDER_JOBS="${RENDER_JOBS:-1}"
UMVS="$UMVS" TEXTURES="$TEXTURES" WIDTH="$RENDER_WIDTH" HEIGHT="$RENDER_HEIGHT" JOBS="$RENDER_JOBS" THREADS=$((RENDER_JOBS > 1 ? 1 : THREADS)) \
  bash "$experiments_dir/render_training_scenes.sh" "$WORK/data/rendered" "$SCENES_PER_RECIPE" 1
supervised_list="$(cat "$WORK/data/rendered/train.txt")"
val_list="$(cat "$WORK/data/rendered/heldout.txt")"

photometric=()
if [ -d "$SHARED/templeRing" ]; then
  [ -f "$WORK/data/templeRing/pair.txt" ] ||
    "$UMVS" import middlebury --data "$SHARED/templeRing" --out "$WORK/data/templeRing" >/dev/null
  photometric=(--data "$WORK/data/templeRing" --supervised-share "$SUPERVISED_SHARE")
else
  echo "[default-model] $SHARED/templeRing not found: supervised on rendered scenes only"
fi
# Real videos, label-free: frames and poses only. The importers read the sensor depth to set each
# view's range and keep it in depth_gt/ for scoring; here every view gets the range a robot without
# a depth sensor configures, and depth_gt/ is removed before training sees the folder.
real_folders=()
for video in $REAL_VIDEOS; do
  dir="$WORK/data/$video"
  if [ ! -f "$dir/pair.txt" ]; then
    rm -rf "$dir"
    base=(--out "$dir" --min-baseline 0.05 --max-baseline 0.3 --depth-range 0.3,8 --count "$REAL_VIDEO_FRAMES")
    case "$video" in
      hololens) "$UMVS" import dvmvs --data "$SHARED/hololens_kitchen/raw/hololens-dataset/000" "${base[@]}" >/dev/null ;;
      tum) "$UMVS" import tum --data "$SHARED/tum_fr3_cabinet_kf/raw/data" --poses truth_cam_poses.txt --associate index \
             --intrinsics "$SHARED/tum_fr3_cabinet_kf/raw/data/TUM3.yaml" "${base[@]}" >/dev/null ;;
      *) echo "[default-model] REAL_VIDEOS: unknown video '$video' (hololens | tum; 7-Scenes is never trained on)" >&2; exit 1 ;;
    esac
  fi
  rm -rf "$dir/depth_gt"
  real_folders+=("$dir")
done
if ((${#real_folders[@]} > 0)); then
  photometric_list="$(IFS=,; echo "${real_folders[*]}")"
  [ -d "$SHARED/templeRing" ] && photometric_list="$WORK/data/templeRing,$photometric_list"
  photometric=(--data "$photometric_list" --supervised-share "$SUPERVISED_SHARE")
fi
if ((${#photometric[@]} == 0)); then
  data=(--data "$supervised_list" --loss supervised)
else
  data=("${photometric[@]}" --supervised-data "$supervised_list" --loss robust)
fi
start=(--network "$NETWORK")
[ -n "$INIT" ] && start=(--init "$INIT")

resume=()
# (a resume passes the same options, --init included: the run refuses any other)
if [ -f "$WORK/run/last.pt" ]; then resume=(--resume); fi
"$UMVS" train "${data[@]}" --val "$val_list" --out "$WORK/run" --width "$WIDTH" --height "$HEIGHT" \
  --num-depth "$NUM_DEPTH" --batch "$BATCH" --device "$DEVICE" --max-minutes "$MAX_MINUTES" --depth-sampling inverse_depth --input-normalization per_image_channel \
  --feature-warp "$FEATURE_WARP" --min-zoom "$MIN_ZOOM" --max-zoom "$MAX_ZOOM" \
  --views-in 3 --views-loss 6 --top-k 3 --preset paper --supervised-weight 0.1 --min-gain 0.25 --max-gain 1.5 \
  --lr "$LR" --lr-schedule "$LR_SCHEDULE" --lr-min "$LR_MIN" --steps "$STEPS" --save-every 500 --val-tuples 15 --seed "$SEED" --threads "$THREADS" "${start[@]}" "${resume[@]}"
echo "[default-model] done: $WORK/run/last.pt (copy it to models/unsup_mvsnet.pt)"
