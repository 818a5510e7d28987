#!/usr/bin/env bash
# Trains the default model models/unsup_mvsnet.pt from random weights, with no real label:
#   * rendered scenes (`umvs synth`: furnished rooms, streets with facades, objects on a table;
#     lighting changes, specular and textureless patches) are supervised on their exact depth
#     (smooth L1 in depth intervals, MVSNet's loss);
#   * real, unlabeled images (Middlebury templeRing, when ../shared/data/templeRing exists) train
#     with the robust photometric loss (paper weights) in the same optimisation;
#   * inputs are normalised per image and channel, and tuples are darkened/brightened by a random
#     exposure gain, so that a dark or low-contrast camera gives the same depth;
#   * planes are spaced in inverse depth (robot scenes span 0.3-10 m and more).
# Held-out rendered scenes (other seeds) are validated on; the model is last.pt (no label of the
# real data picks it). Writes WORK/run/{last.pt,best.pt,train_log.csv,loss_curve.png}; rerunning
# resumes from WORK/run/last.pt.
#
# Usage: scripts/train_default_model.sh [WORK_DIR]
#   environment: UMVS, STEPS (default 6000), THREADS (2), SEED (1), SCENES_PER_RECIPE (8)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
UMVS="${UMVS:-$here/../build/devel/lib/unsup_mvs/umvs}"
WORK="${1:-/tmp/umvs_default_model}"
STEPS="${STEPS:-6000}"
THREADS="${THREADS:-2}"
SEED="${SEED:-1}"
SCENES_PER_RECIPE="${SCENES_PER_RECIPE:-8}"
SHARED="${UMVS_SHARED_DATA:-$here/../../shared/data}"

[ -x "$UMVS" ] || { echo "umvs not found at $UMVS (set UMVS=/path/to/umvs)" >&2; exit 1; }
mkdir -p "$WORK/data"
# glibc keeps freed tensor buffers instead of unmapping them (no page faults on every step) and
# BLAS does not spin threads next to LibTorch's: 2-3x faster steps on a busy 2-core machine.
export MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=4294967296 MALLOC_TOP_PAD_=268435456
export OPENBLAS_NUM_THREADS=1

render() {  # name scene seed views [extra synth options...]
  local name=$1 scene=$2 seed=$3 views=$4
  shift 4
  local dir="$WORK/data/$name"
  if [ ! -f "$dir/pair.txt" ]; then
    echo "[default-model] rendering $name"
    "$UMVS" synth --out "$dir" --scene "$scene" --seed "$seed" --views "$views" --width 320 --height 256 \
      --gt-samples 0 --threads "$THREADS" "$@" >/dev/null
  fi
}

# Training scenes: seeds 1001.. (every 4th without lighting change, otherwise every 3rd with
# specular highlights; every 5th weakly textured); held-out scenes: seeds 2001-2003, never trained on.
supervised_dirs=()
seed=1000
for scene in room facade dtu_like; do
  for ((i = 0; i < SCENES_PER_RECIPE; i++)); do
    seed=$((seed + 1))
    opts=(--lighting-change 1)
    if ((i % 4 == 3)); then opts=(--lighting-change 0); elif ((i % 3 == 2)); then opts+=(--specular); fi
    ((i % 5 == 4)) && opts+=(--texture 0.3)
    render "${scene}_$seed" "$scene" "$seed" 16 "${opts[@]}"
    supervised_dirs+=("$WORK/data/${scene}_$seed")
  done
done
val_dirs=()
for spec in "room 2001" "facade 2002" "dtu_like 2003"; do
  read -r scene s <<<"$spec"
  render "val_${scene}_$s" "$scene" "$s" 10 --lighting-change 1
  val_dirs+=("$WORK/data/val_${scene}_$s")
done

photometric=()
if [ -d "$SHARED/templeRing" ]; then
  [ -f "$WORK/data/templeRing/pair.txt" ] ||
    "$UMVS" import middlebury --data "$SHARED/templeRing" --out "$WORK/data/templeRing" >/dev/null
  photometric=(--data "$WORK/data/templeRing" --supervised-share 0.75)
else
  echo "[default-model] $SHARED/templeRing not found: supervised on rendered scenes only"
fi
join() { local IFS=,; echo "$*"; }
if ((${#photometric[@]} == 0)); then
  data=(--data "$(join "${supervised_dirs[@]}")" --loss supervised)
else
  data=("${photometric[@]}" --supervised-data "$(join "${supervised_dirs[@]}")" --loss robust)
fi

resume=()
[ -f "$WORK/run/last.pt" ] && resume=(--resume)
"$UMVS" train "${data[@]}" --val "$(join "${val_dirs[@]}")" --out "$WORK/run" --width 160 --height 128 \
  --num-depth 32 --depth-sampling inverse_depth --input-normalization per_image_channel \
  --views-in 3 --views-loss 6 --top-k 3 --preset paper --supervised-weight 0.1 --min-gain 0.25 --max-gain 1.5 \
  --steps "$STEPS" --save-every 500 --val-tuples 15 --seed "$SEED" --threads "$THREADS" "${resume[@]}"
echo "[default-model] done: $WORK/run/last.pt (copy it to models/unsup_mvsnet.pt)"
