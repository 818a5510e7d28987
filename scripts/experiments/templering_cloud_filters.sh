#!/usr/bin/env bash
# What the optional PCL filters of `umvs fuse` (io/cloud_filter.h) do on templeRing: points, share
# inside the bounding box and time per filter (docs/fusion.md, "Cleaning the cloud with PCL"), and
# the streaming fusion's voxel hash against pcl::VoxelGrid on the same fused views.
# Usage: scripts/experiments/templering_cloud_filters.sh [WORK_DIR]   (default /tmp/umvs_templering_filters)
# Reuses WORK_DIR/out when it holds `umvs infer` output (the shipped model, 128 planes).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cd "$REPO"
export PATH=/usr/bin:$PATH
WORK=${1:-/tmp/umvs_templering_filters}
THREADS=${THREADS:-2}
BBOX=-0.023121,-0.038009,-0.091940,0.078626,0.121636,-0.017395
mkdir -p "$WORK"
if [ ! -f "$WORK/out/pair.txt" ]; then
  "$UMVS" import middlebury --data "$SHARED/templeRing" --out "$WORK/data" >/dev/null
  "$UMVS" infer --data "$WORK/data" --checkpoint models/unsup_mvsnet.pt --out "$WORK/out" --num-depth 128 \
    --source-combination variance --complete-below-confidence 0 --threads "$THREADS" | tail -1  # the network's own maps, as documented
fi
row() {  # row LABEL [fuse options]: | label | points | % in box | filter s |
  local label=$1; shift
  local log
  log=$("$UMVS" fuse --depth "$WORK/out" --out "$WORK/filtered.pcd" --threads "$THREADS" --bbox "$BBOX" "$@")
  echo "$log" | awk -v label="$label" '
    /^filter / { t += $(NF-1) }
    /inside the bounding box/ { n = $(NF-2); s = $NF; gsub(/[(%)]/, "", s) }
    END { printf "| %s | %d | %.1f | %s |\n", label, n, s, (t > 0 ? sprintf("%.3f", t) : "-") }'
}
echo "| filter (after \`umvs fuse\` defaults) | points | % inside the box | filter time (s) |"
echo "|---|---|---|---|"
row "none"
row "statistical, K = 20, 2.0 std" --sor-k 20 --sor-std 2.0
row "statistical, K = 20, 1.0 std" --sor-k 20 --sor-std 1.0
row "statistical, K = 50, 0.5 std" --sor-k 50 --sor-std 0.5
row "radius 2 mm, >= 4 neighbours" --radius 0.002 --radius-min 4
row "radius 3 mm, >= 8 neighbours" --radius 0.003 --radius-min 8
row "voxel grid 1 mm" --voxel-grid 0.001
row "voxel grid 2 mm" --voxel-grid 0.002
row "statistical K = 20, 2.0 std + voxel grid 1 mm" --sor-k 20 --sor-std 2.0 --voxel-grid 0.001

# Voxel de-duplication, the node's way (core StreamingFusion's hash, inside the fusion, first point
# wins) against pcl::VoxelGrid on the un-deduplicated streaming cloud (centroids), best of 3 runs.
echo
echo "| streaming fusion, window 19 | points | fusion s | voxel grid s |"
echo "|---|---|---|---|"
stream() {  # stream LABEL [fuse options]
  local label=$1; shift
  for run in 1 2 3; do
    "$UMVS" fuse --depth "$WORK/out" --out "$WORK/stream.pcd" --threads "$THREADS" --stream --window 19 "$@" |
      awk '/^fused/ { f = $(NF-5) } /^filter voxel/ { v = $(NF-1); n = $(NF-4) } /^fused/ { p = $5 }
           END { print f, (v == "" ? "-" : v), (n == "" ? p : n) }'
  done | sort -n | head -1 | awk -v label="$label" '{ printf "| %s | %d | %s | %s |\n", label, $3, $1, $2 }'
}
for leaf in 0.001 0.002; do
  stream "no voxel" --voxel-size 0
  stream "hash $leaf" --voxel-size "$leaf"
  stream "pcl::VoxelGrid $leaf after the fusion" --voxel 0 --voxel-grid "$leaf"
done
