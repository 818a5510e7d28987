#!/usr/bin/env bash
# docs/results.md, "the reload rule audited": how often the trainer node's label-free rule
# (decide_reload: held-out photometric loss at least 1 % lower AND multi-view consistency at least
# one point higher) serves a model whose depth got worse, in the node's own setting. Each rendered
# scene is written as a robot log (`umvs bag`, 10 keyframes, every 5th held out); the served model
# is fine-tuned on the training keyframes as a FineTune job does (no depth read), then
# `umvs train --eval-only best.pt --against SERVED` scores both models on the held-out keyframes
# and prints the rule's verdict. The log's depth topic is read only by that scoring, to say whether
# depth really got better (all three of mean abs err, abs rel, within 1 %), worse (all three) or
# neither (mixed).
#
# Usage: scripts/judge_audit.sh [WORK_DIR]
#   environment: UMVS, THREADS (2), STEPS (150), SEEDS ("1 2": --seed of each fine-tuning run),
#                ADAPT ("photometric self"; also "anchored", self-training with --anchor-unconfirmed,
#                and "aggressive", 10x the learning rate),
#                SCENES ("room:301 facade:302 dtu_like:303": `umvs synth` recipe:seed),
#                SERVED (models/unsup_mvsnet.pt),
#                TEXTURES ("none": procedural, the same scenes on every machine; "installed" renders
#                the photographs of scripts/install_textures.sh where they are, another scene; a
#                scene WORK_DIR holds from other textures is rendered again)
# Writes WORK_DIR/audit.md (one row per run and a tally) and prints it.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
UMVS="${UMVS:-$repo/build/devel/lib/unsup_mvs/umvs}"
WORK="${1:-/tmp/umvs_judge_audit}"
THREADS="${THREADS:-2}"
STEPS="${STEPS:-150}"
SEEDS="${SEEDS:-1 2}"
ADAPT="${ADAPT:-photometric self}"
SCENES="${SCENES:-room:301 facade:302 dtu_like:303}"
SERVED="${SERVED:-$repo/models/unsup_mvsnet.pt}"
TEXTURES="${TEXTURES:-none}"
[ -x "$UMVS" ] || { echo "umvs not found at $UMVS (set UMVS=/path/to/umvs)" >&2; exit 1; }
[ -f "$SERVED" ] || { echo "served model not found: $SERVED" >&2; exit 1; }
mkdir -p "$WORK"

adapt_args() {
  case "$1" in
    photometric) echo "" ;;
    self) echo "--self-training-every 25" ;;
    anchored) echo "--self-training-every 25 --anchor-unconfirmed" ;;
    aggressive) echo "--lr 1e-2" ;;
    *) echo "unknown adaptation '$1' (photometric | self | anchored | aggressive)" >&2; return 1 ;;
  esac
}

# The scene's plane-sweep range, from its first camera file (DEPTH_MIN INTERVAL [NUM [DEPTH_MAX]]).
depth_range() {
  awk 'NF { last = $0 } END { n = split(last, f, " ");
       max = n >= 4 ? f[4] : f[1] + f[2] * ((n >= 3 ? f[3] : 192) - 1);
       printf "--depth-min %s --depth-max %s", f[1], max }' "$1/cams/00000000_cam.txt"
}

rows="$WORK/rows.md"
: >"$rows"
start=$(date +%s)
for spec in $SCENES; do
  scene=${spec%%:*} seed=${spec#*:}
  data="$WORK/${scene}_$seed"
  # A render (and its log) made with other textures is another scene: render again.
  if [ -f "$data/pair.txt" ] && [ "$(cat "$data.textures" 2>/dev/null)" != "$TEXTURES" ]; then
    echo "[audit] $data was rendered with other textures than '$TEXTURES': rendering it again" >&2
    rm -rf "$data" "$data.bag" "$WORK/ft/${scene}_${seed}_"* "$WORK/judge/${scene}_${seed}_"*
  fi
  [ -f "$data/pair.txt" ] || "$UMVS" synth --out "$data" --scene "$scene" --seed "$seed" --views 10 --width 320 \
    --height 256 --gt-samples 0 --textures "$TEXTURES" --threads "$THREADS" >"$data.synth.log" 2>&1 ||
    { echo "[audit] rendering failed, see $data.synth.log" >&2; exit 1; }
  echo "$TEXTURES" >"$data.textures"
  [ -f "$data.bag" ] || "$UMVS" bag --data "$data" --out "$data.bag" --depth-topic /camera/depth >"$data.bag.log" 2>&1 ||
    { echo "[audit] writing the log failed, see $data.bag.log" >&2; exit 1; }
  # The trainer node's train_args (config/trainer.yaml) and the scene's depth range.
  common="--bag $data.bag --width 320 --height 256 --num-depth 64 --holdout-every 5 $(depth_range "$data") --threads $THREADS"
  for adapt in $ADAPT; do
    extra=$(adapt_args "$adapt")
    for run_seed in $SEEDS; do
      name="${scene}_${seed}_${adapt}_seed$run_seed"
      out="$WORK/ft/$name"
      if [ ! -f "$out/best.pt" ]; then
        echo "[audit] $adapt fine-tuning on $scene $seed, seed $run_seed ($STEPS steps)" >&2
        rm -rf "$out"
        mkdir -p "$WORK/ft"
        # shellcheck disable=SC2086
        "$UMVS" train $common $extra --init "$SERVED" --seed "$run_seed" --steps "$STEPS" --save-every "$STEPS" \
          --out "$out" >"$out.log" 2>&1 || { echo "[audit] failed, see $out.log" >&2; exit 1; }
      fi
      judged="$WORK/judge/$name"
      if [ ! -f "$judged.log" ] || ! grep -q "^trainer rule:" "$judged.log"; then
        rm -rf "$judged"
        mkdir -p "$WORK/judge"
        # shellcheck disable=SC2086
        "$UMVS" train $common --depth-topic /camera/depth --eval-only "$out/best.pt" --against "$SERVED" \
          --out "$judged" >"$judged.log" 2>&1 || { echo "[audit] scoring failed, see $judged.log" >&2; exit 1; }
      fi
      # eval.csv: the served model's row, then the candidate's; the verdict is the C++ rule's own line.
      verdict=$(sed -n 's/^trainer rule: \(reload\|keep\) .*/\1/p' "$judged.log")
      [ -n "$verdict" ] || { echo "[audit] no 'trainer rule:' verdict in $judged.log" >&2; exit 1; }
      awk -F, -v what="$scene $seed, $adapt, seed $run_seed" -v verdict="$verdict" '
        NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
        NR == 2 { e0 = $col["abs_err"]; r0 = $col["abs_rel"]; w0 = $col["within_1pct"]
                  p0 = $col["photometric"]; c0 = $col["consistent"]; next }
        NR == 3 { e1 = $col["abs_err"]; r1 = $col["abs_rel"]; w1 = $col["within_1pct"]
                  p1 = $col["photometric"]; c1 = $col["consistent"] }
        END {
          improved = (e1 < e0) + (r1 < r0) + (w1 > w0)
          depth = improved == 3 ? "better" : improved == 0 ? "worse" : "mixed"
          printf "| %s | %.3f / %.3f / %.1f -> %.3f / %.3f / %.1f | %s | %.4f -> %.4f | %.1f%% -> %.1f%% | %s |\n",
                 what, e0, r0, 100 * w0, e1, r1, 100 * w1, depth, p0, p1, 100 * c0, 100 * c1, verdict
        }' "$judged/eval.csv" >>"$rows"
    done
  done
done

{
  echo "| run | ground truth on the held-out keyframes, served -> fine-tuned | depth | photometric | consistent | rule |"
  echo "|---|---|---|---|---|---|"
  cat "$rows"
  echo
  awk -F'|' '{ gsub(/ /, "", $4); gsub(/ /, "", $7); n[$7 " " $4]++; total++ }
    END { printf "%d runs: served %d better, %d mixed, %d worse; kept %d better, %d mixed, %d worse\n", total,
          n["reload better"], n["reload mixed"], n["reload worse"], n["keep better"], n["keep mixed"], n["keep worse"] }' "$rows"
  echo "($(( $(date +%s) - start )) s, $THREADS threads, $STEPS steps per run, served model $SERVED, textures $TEXTURES)"
} | tee "$WORK/audit.md"
