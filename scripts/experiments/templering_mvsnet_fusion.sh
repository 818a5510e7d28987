#!/usr/bin/env bash
# MVSNet_pytorch's own templeRing figure (../shared/data/templeRing/PROVENANCE.txt: its model with
# the published weights + its eval.py filter -> 82,775 points) reproduced with umvs:
#   19 views templeR0013..0031, sources in ring order (i-1, i+1, i-2, i+2, ...; 2 for the network,
#   10 for fusion), input 640x480, 128 planes over the tight bounding box's depth in each view
#   +-1 cm (rounded outwards to the mm, as the parity cases), then
#   `umvs fuse --source-rule mvsnet` (eval.py: conf > 0.8, 1 px, 1 %, >= 3 of 10 sources) and,
#   for comparison, the default rule.
# Usage: scripts/experiments/templering_mvsnet_fusion.sh [WORK_DIR]   (default /tmp/umvs_templering_mvsnet)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cd "$REPO"
export PATH=/usr/bin:$PATH
WORK=${1:-/tmp/umvs_templering_mvsnet}
THREADS=${THREADS:-2}
[ -d "$SHARED/templeRing" ] || { echo "no $SHARED/templeRing" >&2; exit 1; }
mkdir -p "$WORK"
"$UMVS" import middlebury --data "$SHARED/templeRing" --out "$WORK/data" >/dev/null
python3 - "$WORK/data" "$SHARED/templeRing/README.txt" <<'EOF'
import glob, itertools, math, os, re, sys
data, readme = sys.argv[1], sys.argv[2]
corners = [tuple(map(float, m)) for m in re.findall(r"\(([-\d.]+) ([-\d.]+) ([-\d.]+)\)", open(readme).read())]
box = list(itertools.product(*zip(*corners[:2])))
ids = sorted(int(os.path.basename(p)[:8]) for p in glob.glob(data + "/cams/*_cam.txt"))
for i in ids:
    path = "%s/cams/%08d_cam.txt" % (data, i)
    lines = open(path).read().split("\n")
    E = [list(map(float, lines[1 + r].split())) for r in range(3)]
    z = [E[2][0] * x + E[2][1] * y + E[2][2] * w + E[2][3] for x, y, w in box]
    lo, hi = math.floor((min(z) - 0.01) * 1000) / 1000, math.ceil((max(z) + 0.01) * 1000) / 1000
    depth_line = next(k for k in range(len(lines) - 1, -1, -1) if lines[k].strip())
    lines[depth_line] = "%.3f %.9f 128 %.3f" % (lo, (hi - lo) / 127, hi)
    open(path, "w").write("\n".join(lines))
with open(data + "/pair.txt", "w") as f:
    f.write("%d\n" % len(ids))
    for n, i in enumerate(ids):
        ring = [n + s * k for k in range(1, len(ids)) for s in (-1, 1)]
        src = [ids[j] for j in ring if 0 <= j < len(ids)][:10]
        f.write("%d\n%d %s\n" % (i, len(src), " ".join("%d 1.0" % j for j in src)))
EOF
"$UMVS" infer --data "$WORK/data" --checkpoint "$SHARED/mvsnet_parity/mvsnet_pytorch_d192.pt" --out "$WORK/out" \
  --views 3 --num-depth 128 --source-combination variance --complete-below-confidence 0 --threads "$THREADS" |
  tail -2  # MVSNet's own maps
BBOX=-0.023121,-0.038009,-0.091940,0.078626,0.121636,-0.017395
for rule in mvsnet neighbours; do
  echo "== umvs fuse --source-rule $rule"
  "$UMVS" fuse --depth "$WORK/out" --data "$WORK/data" --out "$WORK/temple_$rule.ply" --source-rule "$rule" \
    --threads "$THREADS" --bbox "$BBOX" | tail -3
done
