#!/usr/bin/env bash
# TGST real-data experiment on Bandai-Namco-Research-Motiondataset-1 (paper 000 §4, Tables 1-4).
#
#   bash experiments/tgst_bandai/run.sh                 # from anywhere; paths are relative to the repo
#   SHARED=/path/to/shared AE_STEPS=6000 TR_STEPS=10000 bash experiments/tgst_bandai/run.sh
#   EXT_AE_STEPS=12000 bash experiments/tgst_bandai/run.sh   # + the extension with twice the AE steps
#
# 1. split: training folder = every content except BYEBYE and GUIDE, evaluation folder = those two held-out
#    contents (15 styles each); both are folders of symlinks to the shared files (nothing copied);
# 2. train (preset $PRESET): autoencoder, then transformer;
# 3. evaluate on the held-out contents: intra and inter pairs, all four methods, metric validity (Table 1);
# 4. Table 4 ablations: the transformer retrained with one loss term off (reusing the trained autoencoder),
#    evaluated on intra pairs with the soft swap;
# 5. render content / style / result (soft) / ground truth side by side (an inter pair);
# 6. references (no model training involved): Table 1 on the whole dataset (validity_full.py), the
#    "no transfer" rows (baseline_identity.py), autoencoder round trips of the held-out clips (diagnose.py);
# 7. make_tables.py -> out/results/tables.md.
# Every stage is skipped when its output exists (an interrupted training resumes from its checkpoints).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
cd "$REPO"

SHARED="${SHARED:-../shared}"
DATA="${DATA:-$SHARED/data/bandai-namco-1/data}"
JAXGEST="${JAXGEST:-jaxgest}"
PYTHON="${PYTHON:-python3}"
PRESET="${PRESET:-paper}"
AE_STEPS="${AE_STEPS:-6000}"
TR_STEPS="${TR_STEPS:-10000}"
SEED="${SEED:-0}"
HELDOUT="${HELDOUT:-byebye,guide}"
ABLATIONS="${ABLATIONS:-identity cyclic structure appearance}"
GIF_STYLE="${GIF_STYLE:-old}"          # style of the rendered inter pair (chosen before looking at results)
GIF_SECONDS="${GIF_SECONDS:-8}"

OUT="experiments/tgst_bandai/out"
RES="$OUT/results"
TRAIN_DIR="$OUT/data_train"
EVAL_DIR="$OUT/data_eval"
MAIN="$OUT/main"
TIMES="$RES/timings.tsv"
export JAX_COMPILATION_CACHE_DIR="${JAX_COMPILATION_CACHE_DIR:-$HOME/.cache/jaxgest-xla}"
export JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="${JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS:-0.2}"

[ -d "$DATA" ] || { echo "run.sh: no data folder $DATA (set SHARED=... or DATA=...)" >&2; exit 2; }
DATA_ABS="$(cd "$DATA" && pwd)"
mkdir -p "$RES"
[ -f "$TIMES" ] || printf 'stage\tstart_utc\twall_s\n' > "$TIMES"

# stage NAME DONE CMD...: unless DONE (a file or folder) exists, run CMD and append its wall time to timings.tsv
stage() {
  local name="$1" done="$2"; shift 2
  [ -e "$done" ] && { echo "== $name: done ($done exists), skipped"; return 0; }
  local t0; t0=$(date +%s)
  echo "== $(date -u +%H:%M:%S) $name: $*"
  "$@"
  printf '%s\t%s\t%s\n' "$name" "$(date -u -d "@$t0" +%Y-%m-%dT%H:%M:%SZ)" "$(( $(date +%s) - t0 ))" >> "$TIMES"
}

# ---- 1. split (symlinks)
held_re="^dataset-1_($(echo "$HELDOUT" | tr ',' '|'))_"
rm -rf "$TRAIN_DIR" "$EVAL_DIR"
mkdir -p "$TRAIN_DIR" "$EVAL_DIR"
for f in "$DATA_ABS"/dataset-1_*.bvh; do
  b="$(basename "$f")"
  if [[ "$b" =~ $held_re ]]; then ln -s "$f" "$EVAL_DIR/$b"; else ln -s "$f" "$TRAIN_DIR/$b"; fi
done
echo "split: $(ls "$TRAIN_DIR" | wc -l) training clips, $(ls "$EVAL_DIR" | wc -l) held-out clips ($HELDOUT)"

# ---- 2. train
train() {  # train WORKDIR NAME [extra args]: log the one-line summary to results/train_NAME.txt
  local wd="$1" name="$2"; shift 2
  "$JAXGEST" tgst train --data "$TRAIN_DIR" --workdir "$wd" --preset "$PRESET" --ae-steps "$AE_STEPS" \
    --transformer-steps "$TR_STEPS" --seed "$SEED" --ckpt-every 1000 "$@" | tee -a "$RES/train_$name.txt"
}
stage train_main "$MAIN/checkpoints/transformer/$TR_STEPS" train "$MAIN" main

# ---- 3. evaluate (held-out contents only)
evaluate() {  # evaluate WORKDIR JSON [extra args]
  local wd="$1" json="$2"; shift 2
  "$JAXGEST" tgst evaluate --workdir "$wd" --data "$EVAL_DIR" --json "$json" "$@"
}
stage eval_intra "$RES/eval_intra.json" evaluate "$MAIN" "$RES/eval_intra.json" --pairs intra --validity
stage eval_inter "$RES/eval_inter.json" evaluate "$MAIN" "$RES/eval_inter.json" --pairs inter

# ---- 4. Table 4 ablations: transformer retrained with one loss term off, the same autoencoder
for term in $ABLATIONS; do
  wd="$OUT/ablate_$term"
  if [ ! -d "$wd/checkpoints/autoencoder" ]; then
    mkdir -p "$wd/checkpoints"
    cp -r "$MAIN/checkpoints/autoencoder" "$wd/checkpoints/"
  fi
  stage "train_ablate_$term" "$wd/checkpoints/transformer/$TR_STEPS" train "$wd" "ablate_$term" --ablate "$term"
  stage "eval_ablate_$term" "$RES/eval_ablate_$term.json" evaluate "$wd" "$RES/eval_ablate_$term.json" --pairs intra --methods soft
done

# ---- 5. GIF: an inter pair (content BYEBYE neutral, style from GUIDE), ground truth = BYEBYE in that style
content_bvh="$EVAL_DIR/dataset-1_byebye_normal_001.bvh"
style_bvh="$EVAL_DIR/dataset-1_guide_${GIF_STYLE}_001.bvh"
gt_bvh="$EVAL_DIR/dataset-1_byebye_${GIF_STYLE}_001.bvh"
result_bvh="$OUT/transfer_byebye_${GIF_STYLE}_soft.bvh"
stage transfer "$result_bvh" "$JAXGEST" tgst transfer --workdir "$MAIN" --content "$content_bvh" --style "$style_bvh" \
  --out "$result_bvh" --method soft
stage render "$RES/transfer_byebye_${GIF_STYLE}.gif" "$JAXGEST" render "$content_bvh" "$style_bvh" "$result_bvh" "$gt_bvh" \
  --out "$RES/transfer_byebye_${GIF_STYLE}.gif" --max-seconds "$GIF_SECONDS" \
  --titles "content (byebye normal),style (guide ${GIF_STYLE}),result (soft swap),ground truth (byebye ${GIF_STYLE})"

# ---- 6. references without a trained transformer
stage validity_full "$RES/validity_full.json" "$PYTHON" experiments/tgst_bandai/validity_full.py "$DATA" \
  "$RES/validity_full.json" --max-pairs 150 --seed "$SEED"
stage identity "$RES/eval_identity_inter.json" "$PYTHON" experiments/tgst_bandai/baseline_identity.py \
  "$EVAL_DIR" "$RES/eval_identity"
stage diagnose "$RES/diagnose.json" "$PYTHON" experiments/tgst_bandai/diagnose.py "$MAIN" "$EVAL_DIR" \
  "$RES/diagnose.json" "$TRAIN_DIR"

# ---- optional extension (EXT_AE_STEPS=12000): the autoencoder trained further from the main run's checkpoint,
# a transformer retrained on it, intra evaluation and round trips (results ext_ae12k_*: make_tables expects 12000)
EXT_AE_STEPS="${EXT_AE_STEPS:-}"
if [ -n "$EXT_AE_STEPS" ]; then
  EXT="$OUT/ext_ae${EXT_AE_STEPS%000}k"
  EXT_RES="$RES/ext_ae${EXT_AE_STEPS%000}k"
  if [ ! -d "$EXT/checkpoints/autoencoder" ]; then
    mkdir -p "$EXT/checkpoints"
    cp -r "$MAIN/checkpoints/autoencoder" "$EXT/checkpoints/"
  fi
  # (the later --ae-steps overrides train's own)
  stage ext_train "$EXT/checkpoints/transformer/$TR_STEPS" train "$EXT" "ext_ae${EXT_AE_STEPS%000}k" \
    --ae-steps "$EXT_AE_STEPS"
  stage ext_eval_intra "${EXT_RES}_eval_intra.json" evaluate "$EXT" "${EXT_RES}_eval_intra.json" --pairs intra
  stage ext_diagnose "${EXT_RES}_diagnose.json" "$PYTHON" experiments/tgst_bandai/diagnose.py "$EXT" "$EVAL_DIR" \
    "${EXT_RES}_diagnose.json"
fi

# ---- 7. tables
"$PYTHON" experiments/tgst_bandai/make_tables.py "$RES" > "$RES/tables.md"
echo "== $(date -u +%H:%M:%S) done: $RES/tables.md"
