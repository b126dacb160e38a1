#!/usr/bin/env bash
# Table 4 on fit-motion, more seeds: for each seed S given and each loss term, the transformer with that term
# off (2,000 steps, seed S, whole style clip + mirror) on the fit-motion autoencoder of seed S (out/fm_sS),
# then one evaluation of all of them (soft swap, held-out intra and inter pairs, authors' protocol, 0.3 s cut).
# Seed 0 is the section-6 run (out/fm_ablate_TERM). Run from experiments/tgst_bandai/ with the venv active:
#   bash fm_ablate_seeds.sh 1 2
# then: python table4.py out/results/fitmotion_ablate ../eval_fitmotion --seeds 0,1,2
set -euo pipefail
TERMS="identity cyclic structure appearance"
wds=(); labels=()
for S in "$@"; do
  for T in $TERMS; do
    wd="out/fm_ablate_${T}_s${S}"
    mkdir -p "$wd/checkpoints/autoencoder"
    [ -d "$wd/checkpoints/autoencoder/500" ] || cp -r "out/fm_s${S}/checkpoints/autoencoder/500" "$wd/checkpoints/autoencoder/500"
    [ -d "$wd/checkpoints/transformer/2000" ] || python train_transformer.py out/data_train "$wd" 500 2000 "$S" \
        --preset fit-motion --ablate "$T" train.transformer.style_tokens=clip_and_mirror
    wds+=("$wd"); labels+=("${T}_${S}")
    echo "trained $T seed $S $(date +%T)"
  done
done
python eval_seeds.py out/data_eval out/results/fitmotion_ablate/eval_ablate 0.3 "${wds[@]}" \
    --seeds "$(IFS=,; echo "${labels[*]}")" --methods soft
echo "done $(date +%T)"
