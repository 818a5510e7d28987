#!/usr/bin/env bash
# The training-data ablation, small and on the CPU: which label-free data makes the depth?
#   supervised    rendered scenes, smooth L1 on their exact depth only
#   photometric   rendered scenes and the real templeRing images, robust photometric loss only
#                 (the paper's method: no label anywhere)
#   mixed         rendered scenes supervised + templeRing photometric, in one optimisation (the
#                 default model's recipe, scripts/experiments/train_default_model.sh)
#   mixed + self  the mixed model, then self-training on templeRing (its own multi-view
#                 consistent depth as labels, photometric elsewhere; no ground truth read)
# Every run starts from the same random weights (--seed 1) and takes STEPS steps (the self-training
# stage STEPS/4 more). Scored on held-out rendered scenes (seeds 5000.., never trained on) and on the
# living room (../shared/data/livingroom), which no run sees.
#
# Usage: scripts/experiments/ablation_mixed.sh [WORK_DIR]
#   environment: UMVS, STEPS (600), THREADS (1), WIDTH x HEIGHT (160 x 128), NUM_DEPTH (32),
#   RENDERED (a folder of scripts/experiments/render_training_scenes.sh output; rendered into WORK when unset)
# Prints a markdown table and writes it to WORK_DIR/ablation_mixed.md.
set -euo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
WORK="${1:-/tmp/umvs_ablation_mixed}"
STEPS="${STEPS:-600}"
THREADS="${THREADS:-1}"
WIDTH="${WIDTH:-160}"
HEIGHT="${HEIGHT:-128}"
NUM_DEPTH="${NUM_DEPTH:-32}"
require_umvs
for d in templeRing livingroom; do
  [ -d "$SHARED/$d" ] || { echo "needs $SHARED/$d" >&2; exit 1; }
done
mkdir -p "$WORK/data"
export MALLOC_MMAP_THRESHOLD_=33554432 OPENBLAS_NUM_THREADS=1

RENDERED="${RENDERED:-$WORK/data/rendered}"
[ -f "$RENDERED/train.txt" ] || UMVS="$UMVS" WIDTH=320 HEIGHT=256 THREADS="$THREADS" \
  bash "$experiments_dir/render_training_scenes.sh" "$RENDERED" 8 1
rendered="$(cat "$RENDERED/train.txt")"
heldout="$(cat "$RENDERED/heldout.txt")"
[ -f "$WORK/data/templeRing/pair.txt" ] ||
  "$UMVS" import middlebury --data "$SHARED/templeRing" --out "$WORK/data/templeRing" >/dev/null
[ -f "$WORK/data/livingroom/pair.txt" ] ||
  "$UMVS" import rgbd --data "$SHARED/livingroom" --out "$WORK/data/livingroom" --fx 481.2 --fy=-480.0 --cx 319.5 --cy 239.5 >/dev/null
temple="$WORK/data/templeRing"

common=(--width "$WIDTH" --height "$HEIGHT" --num-depth "$NUM_DEPTH" --depth-sampling inverse_depth
        --input-normalization per_image_channel --views-in 3 --views-loss 6 --top-k 3 --preset paper
        --min-gain 0.25 --max-gain 1.5 --save-every "$STEPS" --seed 1 --threads "$THREADS" --overwrite)
train() {  # name args... (skipped when the run is complete)
  local name="$1"; shift
  if [ -f "$WORK/$name/last.pt" ] && grep -q "^$STEPS_OF_RUN," "$WORK/$name/train_log.csv" 2>/dev/null; then return; fi
  echo "training $name ($*)" >&2
  "$UMVS" train "${common[@]}" "$@" --out "$WORK/$name" >/dev/null 2>"$WORK/$name.log"
}
STEPS_OF_RUN=$STEPS
start=$(date +%s)
train supervised --data "$rendered" --loss supervised --steps "$STEPS"
train photometric --data "$rendered,$temple" --loss robust --steps "$STEPS"
train mixed --data "$temple" --supervised-data "$rendered" --supervised-share 0.75 --supervised-weight 0.1 \
  --loss robust --steps "$STEPS"
STEPS_OF_RUN=$((STEPS / 4))
train mixed_self --data "$temple" --init "$WORK/mixed/last.pt" --self-training-every $((STEPS / 8)) \
  --supervised-share 0.75 --supervised-weight 0.1 --loss robust --steps "$STEPS_OF_RUN"

evaluate() {  # name target -> WORK/eval_<target>_<name>/eval.csv
  local out="$WORK/eval_$2_$1"
  [ -f "$out/eval.csv" ] && return
  case "$2" in
    rendered) "$UMVS" train --data "$heldout" --width 320 --height 256 --num-depth 64 --views-loss 4 --top-k 3 \
                --threads "$THREADS" --eval-only "$WORK/$1/last.pt" --out "$out" >/dev/null 2>&1 ;;
    livingroom) "$UMVS" train --data "$WORK/data/livingroom" --width 640 --height 480 --num-depth 128 --views-loss 3 \
                  --top-k 2 --threads "$THREADS" --eval-only "$WORK/$1/last.pt" --out "$out" >/dev/null 2>&1 ;;
  esac
}
cell() {  # name target -> "abs err / abs rel / within 1 %"
  evaluate "$1" "$2"
  awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
           { printf "%.3f / %.3f / %.1f", $col["abs_err"], $col["abs_rel"], 100 * $col["within_1pct"] }' \
    "$WORK/eval_$2_$1/eval.csv"
}
{
  echo "| training data and loss | held-out rendered (4 scenes, 320x256, D=64) | living room (640x480, D=128) |"
  echo "|---|---|---|"
  for spec in "supervised|rendered scenes, supervised only" "photometric|rendered + templeRing, photometric only" \
              "mixed|rendered supervised + templeRing photometric (mixed)" \
              "mixed_self|mixed, then self-training on templeRing"; do
    IFS='|' read -r name label <<<"$spec"
    echo "| $label | $(cell "$name" rendered) | $(cell "$name" livingroom) |"
  done
  echo
  echo "$STEPS steps from the same random weights (self-training: $((STEPS / 4)) more), batch 1, ${WIDTH}x${HEIGHT},"
  echo "D=$NUM_DEPTH in inverse depth, $THREADS threads; wall time $(( $(date +%s) - start )) s"
} | tee "$WORK/ablation_mixed.md"
