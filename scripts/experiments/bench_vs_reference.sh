#!/usr/bin/env bash
# The figures of docs/performance.md, side by side, on THIS machine (run it idle: nothing else on
# the cores). For each input size: `umvs bench` (inference path, published weights, 3 views,
# 2 threads) and, when --reference-dir is given and python3 has torch (Debian: python3-torch),
# MVSNet_pytorch's own models/mvsnet.py with the same weights, 2 threads, run interleaved
# (reference, ours, reference, ours, ...); medians over the repetitions of each one's median.
# Then the autograd path (interleaved inside one process: their ratio), the untuned process
# (--no-tuning: OpenBLAS threads and glibc malloc left alone) and fusion with 1 and 2 threads.
# Prints markdown tables for docs/performance.md.
#
# Usage: scripts/experiments/bench_vs_reference.sh [--reference-dir DIR] [--reps N] [--runs N]
#   DIR: a checkout of github.com/xy-guo/MVSNet_pytorch (only models/ is imported; optional)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cd "$REPO"
export PATH=/usr/bin:$PATH
WEIGHTS=$SHARED/mvsnet_parity/mvsnet_pytorch_d192.pt
REF_DIR=""
REPS=3
RUNS=5
while [ $# -gt 0 ]; do
  case $1 in
    --reference-dir) REF_DIR=$2; shift 2 ;;
    --reps) REPS=$2; shift 2 ;;
    --runs) RUNS=$2; shift 2 ;;
    *) echo "unknown argument $1" >&2; exit 2 ;;
  esac
done
require_umvs
[ -f "$WEIGHTS" ] || { echo "published weights not found: $WEIGHTS" >&2; exit 1; }
if [ -n "$REF_DIR" ] && ! python3 -c "import torch" 2>/dev/null; then
  echo "python3 has no torch (apt-get install python3-torch): reference column skipped" >&2
  REF_DIR=""
fi
TMP=$(mktemp -d /tmp/umvs_bench_vs_ref.XXXXXX)
trap 'rm -rf "$TMP"' EXIT

# One timing of the reference: prints {"median_s": .., "peak_rss_mib": ..}. Same cameras and
# depth range as `umvs bench` (fronto-parallel, 5 cm steps; 1..10 m in inverse depth).
reference_once() {  # W H D
  python3 - "$REF_DIR" "$WEIGHTS" "$1" "$2" "$3" "$RUNS" <<'EOF'
import json, resource, statistics, sys, time
import torch
ref_dir, weights, W, H, D, runs = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
sys.path.insert(0, ref_dir)
from models.mvsnet import MVSNet
torch.set_num_threads(2)
model = MVSNet(refine=False)
model.load_state_dict(torch.load(weights))
model.eval()
V = 3
torch.manual_seed(0)
imgs = torch.rand(1, V, 3, H, W)
proj = torch.zeros(1, V, 4, 4)
for v in range(V):
    K = torch.tensor([[0.8 * W, 0, W / 2 - 0.5], [0, 0.8 * W, H / 2 - 0.5], [0, 0, 1.0]])
    K[:2] *= 0.25
    E = torch.eye(4)[:3]
    E[0, 3] = -0.05 * v
    proj[0, v, :3] = K @ E
    proj[0, v, 3, 3] = 1
inv = torch.linspace(1.0, 0.1, D, dtype=torch.float64)
depth_values = (1.0 / inv).float().unsqueeze(0)
times = []
with torch.no_grad():
    for r in range(1 + runs):
        t0 = time.perf_counter()
        out = model(imgs, proj, depth_values)
        out["depth"].sum().item()
        if r > 0:
            times.append(time.perf_counter() - t0)
print(json.dumps({"median_s": statistics.median(times), "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
EOF
}

ours_once() {  # W H D [extra umvs bench flags]
  local W=$1 H=$2 D=$3
  shift 3
  "$UMVS" bench --width "$W" --height "$H" --num-depth "$D" --views 3 --threads 2 --runs "$RUNS" \
    --checkpoint "$WEIGHTS" --json "$@"
}

# median of a JSON field over lines of a file
field_median() {  # FILE FIELD
  python3 -c 'import json, statistics, sys
vals = [json.loads(l)[sys.argv[2]] for l in open(sys.argv[1]) if l.strip()]
print("%.4f" % statistics.median(vals))' "$1" "$2"
}
stage_medians() {  # FILE
  python3 -c 'import json, statistics, sys
rows = [json.loads(l)["stages_median_s"] for l in open(sys.argv[1]) if l.strip()]
print(", ".join("%s %.4f" % (k, statistics.median(r[k] for r in rows)) for k in ["features", "cost_volume", "unet3d", "regression"]))' "$1"
}

echo "## Network: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(date -u +%F)"
echo
echo "| input | reference s | ours s | ours / reference | peak RSS ref / ours MiB | ours: stages (median s) |"
echo "|---|---|---|---|---|---|"
for size in "160 128 32" "320 256 64" "640 512 128"; do
  set -- $size
  : >"$TMP/ref.jsonl"
  : >"$TMP/ours.jsonl"
  for _ in $(seq "$REPS"); do
    if [ -n "$REF_DIR" ]; then reference_once "$1" "$2" "$3" >>"$TMP/ref.jsonl"; fi
    ours_once "$1" "$2" "$3" >>"$TMP/ours.jsonl"
  done
  ours=$(field_median "$TMP/ours.jsonl" median_s)
  ours_rss=$(field_median "$TMP/ours.jsonl" peak_rss_mib)
  if [ -n "$REF_DIR" ]; then
    ref=$(field_median "$TMP/ref.jsonl" median_s)
    ref_rss=$(field_median "$TMP/ref.jsonl" peak_rss_mib)
    ratio=$(python3 -c "print('%.2f' % ($ours / $ref))")
  else
    ref="n/a"; ref_rss="n/a"; ratio="n/a"
  fi
  echo "| ${1}x${2}, D=$3 | $ref | $ours | $ratio | $ref_rss / $ours_rss | $(stage_medians "$TMP/ours.jsonl") |"
done

echo
echo "## Inference path vs autograd path (interleaved in one process) and process tuning"
echo
echo "| input | fast s | autograd s | autograd / fast | fast, untuned s | minor faults/run tuned / untuned |"
echo "|---|---|---|---|---|---|"
for size in "160 128 32" "320 256 64" "640 512 128"; do
  set -- $size
  both=$(ours_once "$1" "$2" "$3" --path both)
  untuned=$(ours_once "$1" "$2" "$3" --no-tuning)
  tuned=$(ours_once "$1" "$2" "$3")
  python3 - "$1x$2, D=$3" "$both" "$untuned" "$tuned" <<'EOF'
import json, sys
b, u, t = (json.loads(x) for x in sys.argv[2:5])
print("| %s | %.4f | %.4f | %.2f | %.4f | %.0f / %.0f |" % (sys.argv[1], b["median_s"], b["autograd_median_s"],
      b["autograd_over_fast"], u["median_s"], t["minor_faults_per_run"], u["minor_faults_per_run"]))
EOF
done

echo
echo "## Fusion (10 sources, every pixel an estimate)"
echo
echo "| reference | threads | median s / view | stages per view (median s) |"
echo "|---|---|---|---|"
for size in "160 120" "640 512"; do
  set -- $size
  for threads in 1 2; do
    "$UMVS" bench --case fusion --width "$1" --height "$2" --sources 10 --threads "$threads" --runs "$RUNS" --json |
      python3 -c 'import json, sys
r = json.loads(sys.stdin.read()); s = r["stages_median_s_per_view"]
print("| %dx%d | %d | %.5f | ranking %.5f, consistency %.5f, points %.5f |" % (r["width"], r["height"], r["threads"],
      r["median_s_per_view"], s["ranking"], s["consistency"], s["points"]))'
  done
done
