#!/usr/bin/env bash
# docs/results.md, "Real indoor sets": a model on the three real RGB-D sequences of ../shared/data
# (HoloLens kitchen, TUM fr3 cabinet keyframes, 7-Scenes redkitchen), as a user runs it:
# `umvs import` (sources 5-30 cm from the reference), `umvs infer` and `umvs fuse` with their
# defaults, then the sensor depth scores the depth maps (`umvs eval depth --sparsification`) and
# the fused cloud (`umvs eval cloud --gt-depth`, 5 cm). The sensor depth sets each view's depth
# range at import (as the keyframe selector's range follows the last depth map) and scores;
# nothing else reads it.
#
# Usage: scripts/experiments/real_indoor.sh [WORK_DIR]
#   environment: UMVS (build/devel/lib/unsup_mvs/umvs), CHECKPOINT (models/unsup_mvsnet.pt),
#                SETS ("hololens tum sevenscenes"), INFER_ARGS (extra `umvs infer` options),
#                FUSE_ARGS (extra `umvs fuse` options), SHARED (../shared/data), THREADS (0 = all)
# Prints one table row per set; each step's full output stays in WORK_DIR/<set>/*.txt.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
repo="$REPO"
CHECKPOINT=${CHECKPOINT:-$repo/models/unsup_mvsnet.pt}
SETS=${SETS:-hololens tum sevenscenes}
THREADS=${THREADS:-0}
WORK=${1:-/tmp/umvs_real_indoor}
require_umvs
[[ -d "$SHARED" ]] || { echo "real_indoor: no data at $SHARED" >&2; exit 1; }
mkdir -p "$WORK"

import_set() {  # name out
  local base=(--out "$2" --min-baseline 0.05 --max-baseline 0.3)
  case "$1" in
    hololens) "$UMVS" import dvmvs --data "$SHARED/hololens_kitchen/raw/hololens-dataset/000" "${base[@]}" ;;
    tum) "$UMVS" import tum --data "$SHARED/tum_fr3_cabinet_kf/raw/data" --poses truth_cam_poses.txt --associate index \
           --intrinsics "$SHARED/tum_fr3_cabinet_kf/raw/data/TUM3.yaml" "${base[@]}" ;;
    sevenscenes) "$UMVS" import sevenscenes --data "$SHARED/sevenscenes_redkitchen/raw/data" "${base[@]}" ;;
    *) echo "real_indoor: unknown set '$1' (hololens | tum | sevenscenes)" >&2; return 1 ;;
  esac
}

# A figure of a JSON file; nan where it has none (no pixel at a confidence floor).
json_get() {
  /usr/bin/python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
try:
    print(eval(sys.argv[2]))
except TypeError:
    print('nan')" "$@"
}

printf '%-12s %8s %8s %9s %9s %8s %8s %8s %9s\n' set "abs rel" AUSE "conf>=.5" "within10" "F@5cm" precision recall points
for set in $SETS; do
  dir="$WORK/$set"
  [[ -f "$dir/data/pair.txt" ]] || import_set "$set" "$dir/data" >"$dir.import.txt"
  rm -rf "$dir/est"
  # shellcheck disable=SC2086
  "$UMVS" infer --data "$dir/data" --checkpoint "$CHECKPOINT" --out "$dir/est" --threads "$THREADS" ${INFER_ARGS:-} \
    >"$dir/infer.txt" 2>&1 || { echo "real_indoor: umvs infer failed on $set (see $dir/infer.txt)" >&2; exit 1; }
  # shellcheck disable=SC2086
  rm -f "$dir/cloud.ply"
  "$UMVS" fuse --depth "$dir/est" --out "$dir/cloud.ply" ${FUSE_ARGS:-} >"$dir/fuse.txt" 2>&1 \
    || grep -q "no point survived" "$dir/fuse.txt" \
    || { echo "real_indoor: umvs fuse failed on $set (see $dir/fuse.txt)" >&2; exit 1; }
  "$UMVS" eval depth --est "$dir/est" --gt "$dir/data" --rel-thresholds 0.1 --sparsification --json >"$dir/depth.json"
  if [[ -f "$dir/cloud.ply" ]]; then
    "$UMVS" eval cloud --est "$dir/cloud.ply" --gt-depth "$dir/data" --thresholds 0.05 --json >"$dir/cloud.json"
  else  # an empty cloud: nothing to score
    echo '{"fscore":[0],"precision":[0],"recall":[0],"est_points":0}' >"$dir/cloud.json"
  fi
  d="$dir/depth.json" c="$dir/cloud.json"
  printf '%-12s %8.3f %8.3f %8.1f%% %8.1f%% %8.3f %8.3f %8.3f %9d\n' "$set" \
    "$(json_get "$d" "d['overall']['abs_rel']")" "$(json_get "$d" "d['sparsification']['ause']")" \
    "$(json_get "$d" "100*d['confident'][0]['image_share']")" "$(json_get "$d" "100*d['confident'][0]['within']")" \
    "$(json_get "$c" "d['fscore'][0]")" "$(json_get "$c" "d['precision'][0]")" "$(json_get "$c" "d['recall'][0]")" \
    "$(json_get "$c" "d['est_points']")"
done
