#!/usr/bin/env bash
# Trains the default model models/unsup_mvsnet.pt from random weights, without ground truth, with
# the robust photometric loss (paper preset) on synthetic scenes (`umvs synth`: rooms, streets
# and table-top objects with per-view lighting change) plus the Middlebury templeRing images
# (real, unlabeled; used when ../shared/data/templeRing exists). Held-out synthetic scenes with
# exact depth are only monitored (the default model is last.pt: no label picks it).
# Writes WORK/run/{last.pt,best.pt,train_log.csv,loss_curve.png}.
#
# Usage: scripts/train_default_model.sh [WORK_DIR]   (environment: UMVS, STEPS, THREADS, SEED)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
UMVS="${UMVS:-$here/../build/devel/lib/unsup_mvs/umvs}"
WORK="${1:-/tmp/umvs_default_model}"
STEPS="${STEPS:-6000}"
THREADS="${THREADS:-2}"
SEED="${SEED:-1}"
SHARED="${UMVS_SHARED_DATA:-$here/../../shared/data}"

[ -x "$UMVS" ] || { echo "umvs not found at $UMVS (set UMVS=/path/to/umvs)" >&2; exit 1; }
mkdir -p "$WORK/data"

train_dirs=()
val_dirs=()
# name scene seed views: training scenes (seeds 101-112) and held-out ones (seeds 201-203).
for spec in "room_101 room 101 12" "room_102 room 102 12" "room_103 room 103 12" "room_104 room 104 12" \
            "facade_105 facade 105 12" "facade_106 facade 106 12" "facade_107 facade 107 12" \
            "dtu_108 dtu_like 108 12" "dtu_109 dtu_like 109 12" "dtu_110 dtu_like 110 12" \
            "val_room_201 room 201 10" "val_facade_202 facade 202 10" "val_dtu_203 dtu_like 203 10"; do
  read -r name scene seed views <<<"$spec"
  dir="$WORK/data/$name"
  if [ ! -f "$dir/pair.txt" ]; then
    echo "[default-model] rendering $name"
    "$UMVS" synth --out "$dir" --scene "$scene" --seed "$seed" --views "$views" --width 320 --height 256 \
      --lighting-change 1 --gt-samples 0 --threads "$THREADS" >/dev/null
  fi
  case "$name" in val_*) val_dirs+=("$dir") ;; *) train_dirs+=("$dir") ;; esac
done
if [ -d "$SHARED/templeRing" ]; then
  if [ ! -f "$WORK/data/templeRing/pair.txt" ]; then
    "$UMVS" import middlebury --data "$SHARED/templeRing" --out "$WORK/data/templeRing" >/dev/null
  fi
  train_dirs+=("$WORK/data/templeRing")
else
  echo "[default-model] $SHARED/templeRing not found: training on synthetic scenes only"
fi
train=$(IFS=,; echo "${train_dirs[*]}")
val=$(IFS=,; echo "${val_dirs[*]}")

resume=()
[ -f "$WORK/run/last.pt" ] && resume=(--resume)
"$UMVS" train --data "$train" --val "$val" --out "$WORK/run" --width 160 --height 128 --num-depth 32 \
  --views-in 3 --views-loss 6 --loss robust --top-k 3 --preset paper --steps "$STEPS" --save-every 500 \
  --val-tuples 12 --seed "$SEED" --threads "$THREADS" "${resume[@]}"
echo "[default-model] done: $WORK/run/last.pt (copy it to models/unsup_mvsnet.pt)"
