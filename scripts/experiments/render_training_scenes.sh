#!/usr/bin/env bash
# Renders a training set of synthetic scenes with exact depth (for supervised training on
# rendered scenes): N scenes of every recipe (dtu_like, room, corridor, facade) at 160x128 with
# 12-20 views each, with photographic textures and varied camera paths (the recipe's own, a robot
# driving, a robot turning in place, an object-scan orbit or random views), plus a held-out set
# rendered from other seeds. Prints the time it took.
#
#   scripts/experiments/render_training_scenes.sh OUT [N] [N_HELDOUT]      (defaults: N = 8, N_HELDOUT = 2)
#
# Writes OUT/train/<recipe>_<seed>/ and OUT/heldout/<recipe>_<seed>/ (MVSNet folders with
# depth_gt/, see `umvs synth --help`), and OUT/train.txt, OUT/heldout.txt: the folders as one
# comma-separated list for `umvs train --data` / `--val`. A folder already complete (scene.txt is
# written last) is kept, so an interrupted run resumes.
# Environment: UMVS (the binary), TEXTURES (default `installed`: scripts/install_textures.sh; a
# folder list DIR[,DIR]; `none` = procedural), WIDTH, HEIGHT, THREADS (0 = all cores), JOBS
# (scenes rendered at once, default 1).
# Seeds: training 1000 + i, held-out 5000 + i (no other script uses these).
set -euo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
OUT="${1:?usage: scripts/experiments/render_training_scenes.sh OUT [N] [N_HELDOUT]}"
N="${2:-8}"
N_HELDOUT="${3:-2}"
TEXTURES="${TEXTURES:-installed}"
WIDTH="${WIDTH:-160}"
HEIGHT="${HEIGHT:-128}"
THREADS="${THREADS:-0}"
JOBS="${JOBS:-1}"  # scenes rendered at once (each with THREADS threads)

require_umvs
if [ "$TEXTURES" = installed ] && [ ! -d /usr/share/gimp/2.0/patterns ] && [ ! -d /usr/share/backgrounds/mate/nature ]; then
  echo "[render] no photographic textures installed: run scripts/install_textures.sh (or set TEXTURES=none)" >&2
  exit 1
fi

# Camera paths per recipe, taken in turn.
trajectories() {
  case "$1" in
    dtu_like) echo "orbit drive turn random" ;;
    room) echo "forward drive turn random" ;;
    corridor) echo "drive turn forward" ;;
    facade) echo "forward drive turn" ;;
  esac
}

start=$(date +%s)
rendered=0
render_one() {  # set recipe seed trajectory
  local set="$1" recipe="$2" seed="$3" traj="$4"
  local dir="$OUT/$set/${recipe}_$seed" views=$((12 + seed % 9)) extra=()
  ((seed % 3 == 0)) && extra+=(--specular)
  "$UMVS" synth --out "$dir" --scene "$recipe" --seed "$seed" --views "$views" --width "$WIDTH" --height "$HEIGHT" \
    --trajectory "$traj" --lighting-change 1 --textures "$TEXTURES" --gt-samples 0 --threads "$THREADS" \
    "${extra[@]}" >"$OUT/$set/${recipe}_$seed.log" ||
    { echo "[render] $set/${recipe}_$seed failed:" >&2; cat "$OUT/$set/${recipe}_$seed.log" >&2;
      touch "$OUT/$set/${recipe}_$seed.failed"; return 1; }
  echo "[render] $set/${recipe}_$seed: $views views, $traj ($(tail -n 2 "$OUT/$set/${recipe}_$seed.log" | head -n 1))"
}
render_set() {  # set first_seed count
  local set="$1" first="$2" count="$3" dirs=()
  mkdir -p "$OUT/$set"
  rm -f "$OUT/$set"/*.failed
  for recipe in dtu_like room corridor facade; do
    read -r -a trajs <<<"$(trajectories "$recipe")"
    for ((i = 0; i < count; ++i)); do
      local seed=$((first + i))
      local dir="$OUT/$set/${recipe}_$seed"
      if [ ! -f "$dir/scene.txt" ]; then
        while (($(jobs -rp | wc -l) >= JOBS)); do wait -n || true; done
        render_one "$set" "$recipe" "$seed" "${trajs[$((i % ${#trajs[@]}))]}" &
        rendered=$((rendered + 1))
      fi
      dirs+=("$dir")
    done
  done
  wait
  if compgen -G "$OUT/$set/*.failed" >/dev/null; then echo "[render] some scenes failed (see above)" >&2; exit 1; fi
  (IFS=,; echo "${dirs[*]}") >"$OUT/$set.txt"
}

render_set train 1000 "$N"
render_set heldout 5000 "$N_HELDOUT"
elapsed=$(($(date +%s) - start))
echo "[render] $rendered scenes rendered in ${elapsed} s ($((4 * N)) training, $((4 * N_HELDOUT)) held-out in $OUT;" \
  "lists: $OUT/train.txt, $OUT/heldout.txt)"
