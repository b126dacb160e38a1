#!/usr/bin/env bash
# The authors' transformer block layout (post-LN, one LayerNorm per block; model.transformer.variant="authors")
# on the fit-motion autoencoders: for each seed S the 500-step autoencoder of out/fm_sS is copied in and a
# transformer is trained for 2,000 steps (seed S, whole style clip + mirror), then evaluated with the four
# methods and the controls on the held-out pairs (authors' protocol, 0.3 s cut). Run from
# experiments/tgst_bandai/ with the venv active:   bash fm_authors.sh 0 1 2
# Writes out/fma_sS and out/results/eval_fmauthors_{intra,inter}_sS.json; compare with
#   python compare_ae_tables.py out/results eval_fitmotion eval_fmauthors 0,1,2 soft,hard
set -euo pipefail
for S in "$@"; do
  wd="out/fma_s${S}"
  mkdir -p "$wd/checkpoints/autoencoder"
  [ -d "$wd/checkpoints/autoencoder/500" ] || cp -r "out/fm_s${S}/checkpoints/autoencoder/500" "$wd/checkpoints/autoencoder/500"
  [ -d "$wd/checkpoints/transformer/2000" ] || python train_transformer.py out/data_train "$wd" 500 2000 "$S" \
      --preset fit-motion train.transformer.style_tokens=clip_and_mirror "model.transformer.variant='authors'"
  [ -f "out/results/eval_fmauthors_inter_s${S}.json" ] || \
      python eval_seeds.py out/data_eval out/results/eval_fmauthors 0.3 "$wd" --seeds "$S"
  echo "done seed $S $(date +%T)"
done
