#!/usr/bin/env bash
# docs/results.md, "Default model" tables: depth accuracy of the default model (models/) and of the
# published MVSNet_pytorch weights (supervised on DTU; ../shared/data/mvsnet_parity) on held-out
# synthetic scenes and on the living-room frames (exact depth), each before and after unsupervised
# fine-tuning on the target images themselves (Khot et al. 2019, Table 5: no ground truth is used
# for fine-tuning; it is only used to score).
#
# Usage: scripts/results.sh [WORK_DIR]   (environment: UMVS, STEPS_SYNTH, STEPS_LIVINGROOM, THREADS,
#        MODELS="default mvsnet": the models to evaluate and fine-tune; fine-tunings already in WORK_DIR are reused)
# Prints the markdown tables and writes them to WORK_DIR/results.md.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
UMVS="${UMVS:-$here/../build/devel/lib/unsup_mvs/umvs}"
WORK="${1:-/tmp/umvs_results}"
SHARED="${UMVS_SHARED_DATA:-$here/../../shared/data}"
STEPS_SYNTH="${STEPS_SYNTH:-300}"
STEPS_LIVINGROOM="${STEPS_LIVINGROOM:-300}"
THREADS="${THREADS:-2}"
MODELS="${MODELS:-default mvsnet}"
DEFAULT_MODEL="$here/../models/unsup_mvsnet.pt"
MVSNET="$SHARED/mvsnet_parity/mvsnet_pytorch_d192.pt"
[ -x "$UMVS" ] || { echo "umvs not found at $UMVS (set UMVS=/path/to/umvs)" >&2; exit 1; }
[ -f "$MVSNET" ] && [ -d "$SHARED/livingroom" ] || { echo "needs $SHARED/mvsnet_parity and livingroom" >&2; exit 1; }
mkdir -p "$WORK/data"

# Targets: held-out synthetic scenes (seeds used nowhere else) and the living room.
synth_dirs=()
for spec in "room_301 room 301" "facade_302 facade 302" "dtu_303 dtu_like 303"; do
  read -r name scene seed <<<"$spec"
  [ -f "$WORK/data/$name/pair.txt" ] || "$UMVS" synth --out "$WORK/data/$name" --scene "$scene" --seed "$seed" \
    --views 10 --width 320 --height 256 --gt-samples 0 --threads "$THREADS" >/dev/null
  synth_dirs+=("$WORK/data/$name")
done
synth=$(IFS=,; echo "${synth_dirs[*]}")
[ -f "$WORK/data/livingroom/pair.txt" ] || "$UMVS" import rgbd --data "$SHARED/livingroom" --out "$WORK/data/livingroom" >/dev/null

# Per target: evaluation size and loss views (the living room has 5 frames: 3 loss views), and the
# fine-tuning size (synthetic: the default model's training size).
eval_args() {
  case "$1" in
    synth) echo "--data $synth --width 320 --height 256 --num-depth 64 --views-loss 4 --top-k 3" ;;
    livingroom) echo "--data $WORK/data/livingroom --width 640 --height 480 --num-depth 128 --views-loss 3 --top-k 2" ;;
  esac
}
tune_args() {
  case "$1" in
    synth) echo "--data $synth --width 160 --height 128 --num-depth 32 --views-loss 4 --top-k 3 --steps $STEPS_SYNTH" ;;
    livingroom) echo "--data $WORK/data/livingroom --width 320 --height 256 --num-depth 64 --views-loss 3 --top-k 2 --steps $STEPS_LIVINGROOM" ;;
  esac
}
# name checkpoint target -> WORK/eval/name_target/eval.csv
evaluate() {
  # shellcheck disable=SC2046
  "$UMVS" train $(eval_args "$3") --threads "$THREADS" --eval-only "$2" --out "$WORK/eval/$1_$3" >/dev/null 2>&1
}
row() {  # label csv -> "| label | abs err | abs rel | within 1% | photometric |"
  awk -F, -v label="$1" 'NR == 2 { printf "| %s | %.4f | %.3f | %.1f | %.4f |\n", label, $7, $8, 100 * $9, $3 }' "$2"
}

start=$(date +%s)
for target in synth livingroom; do
  for model in $MODELS; do
    ckpt=$DEFAULT_MODEL
    [ "$model" = mvsnet ] && ckpt=$MVSNET
    evaluate "$model" "$ckpt" "$target"
    if [ ! -f "$WORK/ft_${model}_$target/last.pt" ]; then
      echo "[results] fine-tuning $model on $target ($(( $(date +%s) - start )) s so far)"
      # shellcheck disable=SC2046
      "$UMVS" train $(tune_args "$target") --init "$ckpt" --save-every 100000 --threads "$THREADS" --overwrite \
        --out "$WORK/ft_${model}_$target" >/dev/null 2>&1
    fi
    evaluate "${model}_ft" "$WORK/ft_${model}_$target/last.pt" "$target"
  done
done

{
  for target in synth livingroom; do
    if [ "$target" = synth ]; then
      echo "Held-out synthetic scenes (room 301, facade 302, dtu_like 303; 30 reference views, 320x256, D = 64):"
    else
      echo "Living room (../shared/data/livingroom, 4 reference views with 2+ neighbours, 640x480, D = 128):"
    fi
    echo
    echo "| model | mean abs err (m) | abs rel | within 1% (%) | photometric |"
    echo "|---|---|---|---|---|"
    [ -f "$WORK/eval/default_ft_$target/eval.csv" ] || continue
    row "default model (ours, unsupervised, synthetic + templeRing)" "$WORK/eval/default_$target/eval.csv"
    row "default model, fine-tuned on these images (unsupervised)" "$WORK/eval/default_ft_$target/eval.csv"
    row "MVSNet_pytorch weights (supervised, DTU)" "$WORK/eval/mvsnet_$target/eval.csv"
    row "MVSNet_pytorch weights, fine-tuned on these images (unsupervised)" "$WORK/eval/mvsnet_ft_$target/eval.csv"
    echo
  done
  echo "Fine-tuning: $STEPS_SYNTH steps (synthetic, 160x128, D = 32) / $STEPS_LIVINGROOM steps (living room, 320x256, D = 64), robust loss, paper weights; $(( $(date +%s) - start )) s in all on $THREADS CPU threads."
} | tee "$WORK/results.md"
