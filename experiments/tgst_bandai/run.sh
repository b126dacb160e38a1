#!/usr/bin/env bash
# TGST real-data experiment on Bandai-Namco-Research-Motiondataset-1 (paper 000 §4, Tables 1-4).
#
#   bash experiments/tgst_bandai/run.sh                 # from anywhere; paths are relative to the repo
#   SHARED=/path/to/shared AE_STEPS=3000 TR_STEPS=2000 SEEDS="0 1 2" STYLE_TOKENS=clip_and_mirror bash experiments/tgst_bandai/run.sh
#
# 1. split: training folder = every content except BYEBYE and GUIDE, evaluation folder = those two held-out
#    contents (15 styles each); both are folders of symlinks to the shared files (nothing copied);
# 2. autoencoder (preset $PRESET) trained once in out/ae;
# 3. autoencoder diagnostics on the held-out clips (diagnose.py: AE vs PCA-16 vs mean pose per joint, clip
#    ends with and without the padding, speed ratios, round-trip style error; recon_baselines.py);
# 4. swap variants (swap_variants.py): token positions x swap similarity, one transformer each on the same
#    autoencoder checkpoint, soft-swap diagnostics on the inter pairs;
# 5. the preset's transformer for each seed in $SEEDS (out/main_s<seed>, the autoencoder copied in; style data
#    $STYLE_TOKENS: "clip_and_mirror" = the whole style clip + its mirror as one token set, as the authors'
#    trainer, or "window" = random style windows) and the Table 4 ablations on the first seed (transformer
#    retrained with one loss term off);
# 6. evaluations on intra and inter pairs, authors' protocol (cut $TRIM s) for every seed (eval_seeds.py, one
#    process), world protocol and metric validity for the first seed, the ablations;
# 7. summarize.py / table4.py -> out/results/tables.md, table4.md.
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
AE_STEPS="${AE_STEPS:-3000}"   # of the preset's 6,000-step schedule
TR_STEPS="${TR_STEPS:-2000}"
TRIM="${TRIM:-0.3}"            # seconds cut at both ends in the authors' protocol (the paper: 1 s)
VAR_STEPS="${VAR_STEPS:-2000}"
SEEDS="${SEEDS:-0 1 2}"
HELDOUT="${HELDOUT:-byebye,guide}"
ABLATIONS="${ABLATIONS:-identity cyclic structure appearance}"
STYLE_TOKENS="${STYLE_TOKENS:-clip_and_mirror}"  # transformer style data (train.transformer.style_tokens)

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
[ "${SWAP_AE_STEP:-$AE_STEPS}" = "$AE_STEPS" ] || [ -d "$AE/checkpoints/autoencoder/$SWAP_AE_STEP" ] || {
  echo "run.sh: no autoencoder checkpoint $SWAP_AE_STEP for the swap variants (orbax keeps the latest few)" >&2; }

# ---- 3. autoencoder diagnostics (with and without the clip-end padding) and the baselines on original clips
stage diagnose_ae "$RES/diagnose_ae.json" "$PYTHON" experiments/tgst_bandai/diagnose.py "$AE" "$EVAL_DIR" \
  "$RES/diagnose_ae.json" "$TRAIN_DIR" --no-swap --ae-step "$AE_STEPS"
stage diagnose_noedge "$RES/diagnose_ae_noedge.json" "$PYTHON" experiments/tgst_bandai/diagnose.py "$AE" "$EVAL_DIR" \
  "$RES/diagnose_ae_noedge.json" --no-swap --ae-step "$AE_STEPS" --edge-frames 0
stage recon_baselines "$RES/recon_baselines_original.json" "$PYTHON" experiments/tgst_bandai/recon_baselines.py \
  "$TRAIN_DIR" "$EVAL_DIR" "$RES/recon_baselines_original.json"

# ---- 4. swap variants on one autoencoder checkpoint (the recorded run used the 500-step one, SWAP_AE_STEP=500)
SWAP_AE_STEP="${SWAP_AE_STEP:-$AE_STEPS}"
stage swap_variants "$RES/swap_variants_ae$SWAP_AE_STEP.json" bash -c "'$PYTHON' experiments/tgst_bandai/swap_variants.py \
  '$AE' '$SWAP_AE_STEP' '$TRAIN_DIR' '$EVAL_DIR' '$OUT/swapvar_ae$SWAP_AE_STEP' --steps '$VAR_STEPS' --preset '$PRESET' \
  && cp '$OUT/swapvar_ae$SWAP_AE_STEP/swap_variants.json' '$RES/swap_variants_ae$SWAP_AE_STEP.json'"

# ---- 5. the preset's transformer, one per seed, and Table 4's ablations (first seed), on the same autoencoder
with_ae() {  # with_ae WORKDIR: the trained autoencoder copied in
  if [ ! -d "$1/checkpoints/autoencoder/$AE_STEPS" ]; then
    mkdir -p "$1/checkpoints/autoencoder"
    cp -r "$AE/checkpoints/autoencoder/$AE_STEPS" "$1/checkpoints/autoencoder/"
  fi
}
train_tr() {  # train_tr WORKDIR SEED [--ablate TERM]
  local wd="$1" seed="$2"; shift 2
  with_ae "$wd"
  "$PYTHON" experiments/tgst_bandai/train_transformer.py "$TRAIN_DIR" "$wd" "$AE_STEPS" "$TR_STEPS" "$seed" "$@" \
    --preset "$PRESET" "train.transformer.style_tokens=$STYLE_TOKENS"
}
first_seed="${SEEDS%% *}"
seed_dirs=(); seed_labels=()
for seed in $SEEDS; do
  stage "train_s$seed" "$OUT/main_s$seed/checkpoints/transformer/$TR_STEPS" train_tr "$OUT/main_s$seed" "$seed"
  seed_dirs+=("$OUT/main_s$seed"); seed_labels+=("$seed")
done
for term in $ABLATIONS; do
  stage "train_ablate_$term" "$OUT/ablate_$term/checkpoints/transformer/$TR_STEPS" train_tr "$OUT/ablate_$term" \
    "$first_seed" --ablate "$term"
done

# ---- 6. evaluations (authors' protocol, cut $TRIM s): all seeds in one process, then the world protocol and the
#         metric validity for the first seed, then the ablations
labels=$(IFS=,; echo "${seed_labels[*]}")
stage eval_seeds "$RES/eval_inter_s${seed_labels[-1]}.json" "$PYTHON" experiments/tgst_bandai/eval_seeds.py "$EVAL_DIR" \
  "$RES/eval" "$TRIM" "${seed_dirs[@]}" --seeds "$labels"
for p in intra inter; do
  stage "eval_${p}_world" "$RES/eval_${p}_world_s$first_seed.json" "$JAXGEST" tgst evaluate \
    --workdir "$OUT/main_s$first_seed" --data "$EVAL_DIR" --json "$RES/eval_${p}_world_s$first_seed.json" --pairs "$p" \
    --methods soft,hard,adain,avatarnet,autoencoder --protocol world
done
stage validity "$RES/validity_s$first_seed.json" "$JAXGEST" tgst evaluate --workdir "$OUT/main_s$first_seed" \
  --data "$EVAL_DIR" --json "$RES/validity_s$first_seed.json" --pairs intra --methods soft --trim "$TRIM" --validity
abl_dirs=(); for term in $ABLATIONS; do abl_dirs+=("$OUT/ablate_$term"); done
stage eval_ablate "$RES/eval_ablate_inter_s${ABLATIONS##* }.json" "$PYTHON" experiments/tgst_bandai/eval_seeds.py \
  "$EVAL_DIR" "$RES/eval_ablate" "$TRIM" "${abl_dirs[@]}" --seeds "$(echo $ABLATIONS | tr ' ' ',')"

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
"$PYTHON" experiments/tgst_bandai/table4.py "$RES" > "$RES/table4.md"
echo "== $(date -u +%H:%M:%S) done: $RES/tables.md"
