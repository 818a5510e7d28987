#!/usr/bin/env bash
# docs/results.md, "The reload rule audited": how often the trainer node's label-free rule
# (decide_reload: held-out photometric loss at least 1 % lower AND multi-view consistency at least
# one point higher) serves a model whose depth got worse, in the node's own setting. Each rendered
# scene is written as a robot log (`umvs bag`, 10 keyframes, every 5th held out); the served model
# is fine-tuned on the training keyframes as a FineTune job does (no depth read), then
# `umvs train --eval-only best.pt --against SERVED` scores both models on the held-out keyframes
# and prints the rule's verdict. The log's depth topic is read only by that scoring, to say whether
# depth really got better (all three of mean abs err, abs rel, within 1 %), worse (all three) or
# neither (mixed). Two held-out keyframes are little ground truth, and their neighbours are
# training keyframes; so both models are also scored on a second pass through the same scene
# (`umvs synth --path-seed`, 10 keyframes no run saw, each judged against the others).
#
# Usage: scripts/experiments/judge_audit.sh [WORK_DIR]
#   environment: UMVS, THREADS (2), STEPS (150), SEEDS ("1 2": --seed of each fine-tuning run),
#                ADAPT ("photometric self": photometric, and plain self-training (--anchor-unconfirmed 0);
#                also "confident", self-training as umvs train does it by default (anchored
#                where the start model is confident, --anchor-min-confidence 0.5), "anchored",
#                every unconfirmed pixel anchored (--anchor-min-confidence 0), "unseen",
#                "confident" plus the pixels no loss view sees (--anchor-unseen 1), "teacher",
#                "confident" with labels, anchors and the rule's consistency from one pass per
#                source as well (--source-combination most_confident), and "aggressive", 10x the
#                learning rate),
#                SCENES ("room:301 facade:302 dtu_like:303": `umvs synth` recipe:seed),
#                SERVED (models/unsup_mvsnet.pt),
#                TEXTURES ("none": procedural, the same scenes on every machine; "installed" renders
#                the photographs of scripts/install_textures.sh where they are, another scene; a
#                scene WORK_DIR holds from other textures is rendered again),
#                SECOND_PASS (1; 0 = score the held-out keyframes only)
# Writes WORK_DIR/audit.md (one row per run and a tally) and prints it.
set -euo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
repo="$REPO"
WORK="${1:-/tmp/umvs_judge_audit}"
THREADS="${THREADS:-2}"
STEPS="${STEPS:-150}"
SEEDS="${SEEDS:-1 2}"
ADAPT="${ADAPT:-photometric self}"
SCENES="${SCENES:-room:301 facade:302 dtu_like:303}"
SERVED="${SERVED:-$repo/models/unsup_mvsnet.pt}"
TEXTURES="${TEXTURES:-none}"
SECOND_PASS="${SECOND_PASS:-1}"
require_umvs
[ -f "$SERVED" ] || { echo "served model not found: $SERVED" >&2; exit 1; }
mkdir -p "$WORK"

adapt_args() {
  case "$1" in
    photometric) echo "" ;;
    self) echo "--self-training-every 25 --anchor-unconfirmed 0" ;;
    anchored) echo "--self-training-every 25 --anchor-unconfirmed 1 --anchor-min-confidence 0" ;;
    confident) echo "--self-training-every 25 --anchor-unconfirmed 1 --anchor-min-confidence 0.5" ;;
    unseen) echo "--self-training-every 25 --anchor-unconfirmed 1 --anchor-min-confidence 0.5 --anchor-unseen 1" ;;
    teacher) echo "--self-training-every 25 --anchor-unconfirmed 1 --anchor-min-confidence 0.5 $(judge_args teacher)" ;;
    aggressive) echo "--lr 1e-2" ;;
    *) echo "unknown adaptation '$1' (photometric | self | anchored | confident | unseen | teacher | aggressive)" >&2; return 1 ;;
  esac
}
# How the rule's consistency makes depth maps for an adaptation (as its run made its labels).
judge_args() {
  case "$1" in
    teacher) echo "--source-combination most_confident" ;;
    *) echo "" ;;
  esac
}

# render FOLDER SCENE SEED [umvs synth options]: the scene as a robot log, FOLDER.bag.
render() {
  local data=$1 scene=$2 seed=$3
  shift 3
  [ -f "$data/pair.txt" ] || "$UMVS" synth --out "$data" --scene "$scene" --seed "$seed" --views 10 --width 320 \
    --height 256 --gt-samples 0 --textures "$TEXTURES" --threads "$THREADS" "$@" >"$data.synth.log" 2>&1 ||
    { echo "[audit] rendering failed, see $data.synth.log" >&2; exit 1; }
  echo "$TEXTURES" >"$data.textures"
  [ -f "$data.bag" ] || "$UMVS" bag --data "$data" --out "$data.bag" --depth-topic /camera/depth >"$data.bag.log" 2>&1 ||
    { echo "[audit] writing the log failed, see $data.bag.log" >&2; exit 1; }
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
    rm -rf "$data" "$data.bag" "$data.pass2" "$data.pass2.bag" "$WORK/ft/${scene}_${seed}_"* \
      "$WORK/judge/${scene}_${seed}_"* "$WORK/judge2/${scene}_${seed}_"*
  fi
  render "$data" "$scene" "$seed"
  # The trainer node's train_args (config/trainer.yaml) less its --self-training-every, which ADAPT
  # chooses ("confident" is `umvs train`'s default self-training, "photometric" the loss alone), and the
  # scene's depth range.
  common="--bag $data.bag --width 320 --height 256 --num-depth 64 --holdout-every 5 $(depth_range "$data") --threads $THREADS"
  if [ "$SECOND_PASS" = 1 ]; then
    render "$data.pass2" "$scene" "$seed" --path-seed $((seed + 1000))
    second="--bag $data.pass2.bag --width 320 --height 256 --num-depth 64 --holdout-every 0 $(depth_range "$data.pass2")"
    second="$second --threads $THREADS --depth-topic /camera/depth"
  fi
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
        "$UMVS" train $common $(judge_args "$adapt") --depth-topic /camera/depth --eval-only "$out/best.pt" \
          --against "$SERVED" --out "$judged" >"$judged.log" 2>&1 || { echo "[audit] scoring failed, see $judged.log" >&2; exit 1; }
      fi
      # The same two models on the second pass: ground truth only, the rule's verdict stays the one above.
      judged2="$WORK/judge2/$name"
      if [ "$SECOND_PASS" = 1 ] && [ ! -f "$judged2/eval.csv" ]; then
        rm -rf "$judged2"
        mkdir -p "$WORK/judge2"
        # shellcheck disable=SC2086
        "$UMVS" train $second --eval-only "$out/best.pt" --against "$SERVED" --out "$judged2" >"$judged2.log" 2>&1 ||
          { echo "[audit] scoring the second pass failed, see $judged2.log" >&2; exit 1; }
      fi
      # eval.csv: the served model's row, then the candidate's; the verdict is the C++ rule's own line.
      verdict=$(sed -n 's/^trainer rule: \(reload\|keep\) .*/\1/p' "$judged.log")
      [ -n "$verdict" ] || { echo "[audit] no 'trainer rule:' verdict in $judged.log" >&2; exit 1; }
      files=("$judged/eval.csv")
      if [ "$SECOND_PASS" = 1 ]; then files+=("$judged2/eval.csv"); fi
      awk -F, -v what="$scene $seed, $adapt, seed $run_seed" -v verdict="$verdict" '
        FNR == 1 { ++file; for (i = 1; i <= NF; ++i) col[$i] = i; next }
        FNR == 2 || FNR == 3 { m = FNR - 2
          e[file, m] = $col["abs_err"]; r[file, m] = $col["abs_rel"]; w[file, m] = $col["within_1pct"]
          if (file == 1) { p[m] = $col["photometric"]; c[m] = $col["consistent"] } }
        function scores(f,   improved) {
          improved = (e[f, 1] < e[f, 0]) + (r[f, 1] < r[f, 0]) + (w[f, 1] > w[f, 0])
          return sprintf("%.3f / %.3f / %.1f -> %.3f / %.3f / %.1f | %s", e[f, 0], r[f, 0], 100 * w[f, 0],
                         e[f, 1], r[f, 1], 100 * w[f, 1], improved == 3 ? "better" : improved == 0 ? "worse" : "mixed")
        }
        END {
          printf "| %s | %s |%s %.4f -> %.4f | %.1f%% -> %.1f%% | %s |\n", what, scores(1),
                 file == 2 ? " " scores(2) " |" : "", p[0], p[1], 100 * c[0], 100 * c[1], verdict
        }' "${files[@]}" >>"$rows"
    done
  done
done

# tally COLUMN NAME: how the rule's verdicts split by the depth verdict in that column of the rows.
tally() {
  awk -F'|' -v at="$1" -v what="$2" '{ d = $at; v = $(NF - 1); gsub(/ /, "", d); gsub(/ /, "", v); n[v " " d]++; total++ }
    END { printf "%d runs (%s): served %d better, %d mixed, %d worse; kept %d better, %d mixed, %d worse\n", total, what,
          n["reload better"], n["reload mixed"], n["reload worse"], n["keep better"], n["keep mixed"], n["keep worse"] }' "$rows"
}
{
  if [ "$SECOND_PASS" = 1 ]; then
    echo "| run | held-out keyframes, served -> fine-tuned | depth | second pass, served -> fine-tuned | depth | photometric | consistent | rule |"
    echo "|---|---|---|---|---|---|---|---|"
  else
    echo "| run | ground truth on the held-out keyframes, served -> fine-tuned | depth | photometric | consistent | rule |"
    echo "|---|---|---|---|---|---|"
  fi
  cat "$rows"
  echo
  tally 4 "held-out keyframes"
  if [ "$SECOND_PASS" = 1 ]; then tally 6 "second pass"; fi
  echo "($(( $(date +%s) - start )) s, $THREADS threads, $STEPS steps per run, served model $SERVED, textures $TEXTURES)"
} | tee "$WORK/audit.md"
