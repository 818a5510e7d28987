#!/usr/bin/env bash
# The data-parallel table of docs/performance.md on THIS machine (run it idle). One rendered scene
# at 160x128, D=32; `umvs train` from the same initial model for STEPS steps as
#   1 process,  --batch 1, all cores
#   1 process,  --batch 2, all cores            (the work of one step of 2 ranks)
#   --nproc 2,  --batch 1 each, cores/2 threads each (Gloo over loopback)
# and the median seconds per step (train_log.csv, steps after the first 3). Prints a markdown table.
#
# Usage: scripts/experiments/bench_data_parallel.sh [STEPS]   (default 20)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cd "$REPO"
export PATH=/usr/bin:$PATH
STEPS=${1:-20}
require_umvs
WORK=$(mktemp -d /tmp/umvs_bench_dp.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
CORES=$(nproc)
HALF=$(( CORES / 2 > 0 ? CORES / 2 : 1 ))

"$UMVS" synth --out "$WORK/scene" --width 160 --height 128 --views 8 >/dev/null 2>&1
COMMON=(--data "$WORK/scene" --width 160 --height 128 --num-depth 32 --views-loss 3 --top-k 2
        --steps "$STEPS" --save-every 100000 --seed 1)
# The initial model of all runs (step 0 of a run is its random initial weights).
"$UMVS" train "${COMMON[@]}" --steps 0 --out "$WORK/init" >/dev/null 2>&1

median_step_seconds() {  # LOG: median of the `seconds` column over the steps after the first 3
  awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) if ($i == "seconds") c = i; next }
           NR > 4 { print $c }' "$1" | sort -g | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'
}

run() {  # FOLDER NAME TUPLES_PER_STEP ARGS...
  local dir=$1 name=$2 tuples=$3
  shift 3
  "$UMVS" train "${COMMON[@]}" --init "$WORK/init/last.pt" --out "$WORK/$dir" "$@" >"$WORK/$dir.log" 2>&1 ||
    { cat "$WORK/$dir.log" >&2; exit 1; }
  local s
  s=$(median_step_seconds "$WORK/$dir/train_log.csv")
  awk -v n="$name" -v s="$s" -v t="$tuples" \
    'BEGIN { printf "| %s | %d | %.3f | %.2f | %.2f |\n", n, t, s, 1 / s, t / s }'
}

echo "| run (160x128, D=32, $CORES cores) | tuples per step | s per step (median) | steps/s | tuples/s |"
echo "|---|---|---|---|---|"
run one_b1 "1 process, batch 1, $CORES threads" 1 --batch 1 --threads "$CORES"
run one_b2 "1 process, batch 2, $CORES threads" 2 --batch 2 --threads "$CORES"
run one_micro "1 process, batch 2 in micro-batches of 1, $CORES threads" 2 --batch 2 --micro-batch 1 --threads "$CORES"
run two_ranks "2 ranks (--nproc 2), batch 1 each, $HALF threads each" 2 --nproc 2 --batch 1 --threads "$HALF"
grep -h "all-reduces" "$WORK"/*.log | head -1
