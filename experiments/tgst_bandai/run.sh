#!/usr/bin/env bash
# TGST real-data experiment on Bandai-Namco-Research-Motiondataset-1 (paper 000 §4, Tables 1-4).
#
#   bash experiments/tgst_bandai/run.sh                 # from anywhere; paths are relative to the repo
#   SHARED=/path/to/shared AE_STEPS=6000 TR_STEPS=4000 SEEDS="0 1 2" bash experiments/tgst_bandai/run.sh
#
# 1. split: training folder = every content except BYEBYE and GUIDE, evaluation folder = those two held-out
#    contents (15 styles each); both are folders of symlinks to the shared files (nothing copied);
# 2. autoencoder (preset $PRESET) trained once in out/ae;
# 3. autoencoder diagnostics on the held-out clips (diagnose.py: AE vs PCA-16 vs mean pose per joint, clip
#    ends, speed ratios, round-trip style error);
# 4. swap variants (swap_variants.py): token positions x swap similarity, one transformer each on the same
#    autoencoder, soft-swap diagnostics on the inter pairs;
# 5. the preset's transformer for each seed in $SEEDS (out/main_s<seed>, the autoencoder copied in), evaluated
#    on intra and inter pairs under the authors' protocol (and the world protocol for the first seed);
# 6. Table 4 ablations on the first seed (transformer retrained with one loss term off);
# 7. summarize.py -> out/results/tables.md.
# Every stage is skipped when its output exists (an interrupted training resumes from its checkpoints).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
cd "$REPO"

SHARED="${SHARED:-../shared}"
DATA="${DATA:-$SHARED/data/bandai-namco-1/data}"
JAXGEST="${JAXGEST:-jaxgest}"
PYTHON="${PYTHON:-python3}"
PRESET="${PRESET:-fit}"
AE_STEPS="${AE_STEPS:-6000}"
TR_STEPS="${TR_STEPS:-4000}"
VAR_STEPS="${VAR_STEPS:-2000}"
SEEDS="${SEEDS:-0 1 2}"
HELDOUT="${HELDOUT:-byebye,guide}"
ABLATIONS="${ABLATIONS:-identity cyclic structure appearance}"

OUT="experiments/tgst_bandai/out"
RES="$OUT/results"
TRAIN_DIR="$OUT/data_train"
EVAL_DIR="$OUT/data_eval"
AE="$OUT/ae"
TIMES="$RES/timings.tsv"
export JAX_COMPILATION_CACHE_DIR="${JAX_COMPILATION_CACHE_DIR:-$HOME/.cache/jaxgest-xla}"

[ -d "$DATA" ] || { echo "run.sh: no data folder $DATA (set SHARED=... or DATA=...)" >&2; exit 2; }
DATA_ABS="$(cd "$DATA" && pwd)"
mkdir -p "$RES"
[ -f "$TIMES" ] || printf 'stage\tstart_utc\twall_s\n' > "$TIMES"

stage() {  # stage NAME DONE CMD...: unless DONE exists, run CMD and append its wall time to timings.tsv
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

# ---- 2. autoencoder
stage train_ae "$AE/checkpoints/autoencoder/$AE_STEPS" "$JAXGEST" tgst train --data "$TRAIN_DIR" --workdir "$AE" \
  --preset "$PRESET" --ae-steps "$AE_STEPS" --transformer-steps 0 --seed 0 --ckpt-every 500

# ---- 3. autoencoder diagnostics
stage diagnose_ae "$RES/diagnose_ae.json" "$PYTHON" experiments/tgst_bandai/diagnose.py "$AE" "$EVAL_DIR" \
  "$RES/diagnose_ae.json" "$TRAIN_DIR" --no-swap

# ---- 4. swap variants on the same autoencoder
stage swap_variants "$RES/swap_variants.json" bash -c "'$PYTHON' experiments/tgst_bandai/swap_variants.py '$AE' \
  '$AE_STEPS' '$TRAIN_DIR' '$EVAL_DIR' '$OUT/swapvar' --steps '$VAR_STEPS' --preset '$PRESET' \
  && cp '$OUT/swapvar/swap_variants.json' '$RES/swap_variants.json'"

# ---- 5. the preset's transformer, one per seed; evaluations under the authors' protocol
evaluate() {  # evaluate WORKDIR JSON [extra args]
  local wd="$1" json="$2"; shift 2
  "$JAXGEST" tgst evaluate --workdir "$wd" --data "$EVAL_DIR" --json "$json" "$@"
}
with_ae() {  # with_ae WORKDIR: the trained autoencoder copied in
  if [ ! -d "$1/checkpoints/autoencoder/$AE_STEPS" ]; then
    mkdir -p "$1/checkpoints/autoencoder"
    cp -r "$AE/checkpoints/autoencoder/$AE_STEPS" "$1/checkpoints/autoencoder/"
  fi
}
first_seed="${SEEDS%% *}"
for seed in $SEEDS; do
  wd="$OUT/main_s$seed"
  with_ae "$wd"
  stage "train_s$seed" "$wd/checkpoints/transformer/$TR_STEPS" "$JAXGEST" tgst train --data "$TRAIN_DIR" \
    --workdir "$wd" --preset "$PRESET" --ae-steps "$AE_STEPS" --transformer-steps "$TR_STEPS" --seed "$seed" \
    --ckpt-every "$TR_STEPS"
  stage "eval_intra_s$seed" "$RES/eval_intra_s$seed.json" evaluate "$wd" "$RES/eval_intra_s$seed.json" \
    --pairs intra --methods soft,hard,adain,avatarnet,autoencoder
  stage "eval_inter_s$seed" "$RES/eval_inter_s$seed.json" evaluate "$wd" "$RES/eval_inter_s$seed.json" \
    --pairs inter --methods soft,hard,adain,avatarnet,autoencoder
done
wd="$OUT/main_s$first_seed"
stage eval_intra_world "$RES/eval_intra_world.json" evaluate "$wd" "$RES/eval_intra_world.json" --pairs intra \
  --protocol world
stage eval_inter_world "$RES/eval_inter_world.json" evaluate "$wd" "$RES/eval_inter_world.json" --pairs inter \
  --protocol world

# ---- 6. Table 4 ablations (first seed)
for term in $ABLATIONS; do
  wd="$OUT/ablate_$term"
  with_ae "$wd"
  stage "train_ablate_$term" "$wd/checkpoints/transformer/$TR_STEPS" "$JAXGEST" tgst train --data "$TRAIN_DIR" \
    --workdir "$wd" --preset "$PRESET" --ae-steps "$AE_STEPS" --transformer-steps "$TR_STEPS" \
    --seed "$first_seed" --ckpt-every "$TR_STEPS" --ablate "$term"
  stage "eval_ablate_$term" "$RES/eval_ablate_$term.json" evaluate "$wd" "$RES/eval_ablate_$term.json" \
    --pairs all --methods soft
done

# ---- 7. tables
{
  for p in intra inter; do
    t=$([ "$p" = intra ] && echo 2 || echo 3)
    files=$(for s in $SEEDS; do echo "$RES/eval_${p}_s$s.json"; done)
    # shellcheck disable=SC2086
    "$PYTHON" experiments/tgst_bandai/summarize.py "Table $t analogue ($p-scenario, held-out contents)" "$t" $files
    echo
  done
} > "$RES/tables.md"
echo "== $(date -u +%H:%M:%S) done: $RES/tables.md"
