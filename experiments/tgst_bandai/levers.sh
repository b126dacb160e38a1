#!/usr/bin/env bash
# Transformer levers on the fit-pca autoencoder (1,500 steps, seed 0 of out/fitpca_main_s0): one transformer per
# lever (2,000 steps, seed $SEED, whole style clip + mirror), evaluated with soft and hard swaps on the held-out
# intra and inter pairs (authors' protocol, 0.3 s cut). Run from experiments/tgst_bandai/ with the venv active:
#   SEED=0 bash levers.sh NAME "override ..." [NAME "override ..." ...]
# e.g. bash levers.sh lstruct10 "train.transformer.lambda_structure=10.0" scaled "model.swap_similarity='scaled'"
# Writes out/lever_NAME_sSEED (workdir) and out/results/lever_NAME_{intra,inter}_sSEED.json; compare with
#   python compare_ae_tables.py out/results eval_fitpca lever_NAME 0:0 soft,hard
set -euo pipefail
SEED="${SEED:-0}"
STEPS="${STEPS:-2000}"
AE="${AE:-out/fitpca_main_s0/checkpoints/autoencoder/1500}"
while [ $# -ge 2 ]; do
  name="$1"; read -r -a ov <<< "$2"; shift 2
  wd="out/lever_${name}_s${SEED}"
  mkdir -p "$wd/checkpoints/autoencoder"
  [ -d "$wd/checkpoints/autoencoder/1500" ] || cp -r "$AE" "$wd/checkpoints/autoencoder/1500"
  if [ ! -d "$wd/checkpoints/transformer/$STEPS" ]; then
    python train_transformer.py out/data_train "$wd" 1500 "$STEPS" "$SEED" --preset fit-pca \
      train.autoencoder.learning_rate=0.0003 train.autoencoder.lr_decay_steps=1500 \
      train.transformer.style_tokens=clip_and_mirror "${ov[@]}"
  fi
  [ -f "out/results/lever_${name}_inter_s${SEED}.json" ] || \
    python eval_seeds.py out/data_eval "out/results/lever_${name}" 0.3 "$wd" --seeds "$SEED" --methods soft,hard
  echo "done $name $(date +%T)"
done
