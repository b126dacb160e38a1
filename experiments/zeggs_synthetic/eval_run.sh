#!/usr/bin/env bash
# Every measurement of the initial-pose table for one trained run, from experiments/zeggs_synthetic/:
#   bash eval_run.sh RUN        # reads out/RUN, writes out/{static_style,eval_pooled,leakage_pooled}_RUN.json,
#                               # out/eval_RUN.json and out/eval_RUN_heldout.json
# Needs out/data (synth --seed 0), out/data_heldout (--seed 1) and out/probe_data/seedK (--seed K, K = 1..16).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
RUN=$1; W=out/$RUN
J=(python -m jaxgest.cli)
held=(out/data_heldout); for k in $(seq 2 8); do held+=(out/probe_data/seed$k); done
probe=(); for k in $(seq 1 16); do probe+=(out/probe_data/seed$k); done
t0=$(date +%s)
python static_style.py --workdir "$W" $(printf -- '--data %s ' "${held[@]}") --json "out/static_style_$RUN.json" > "out/static_style_$RUN.md"
"${J[@]}" zeggs evaluate --workdir "$W" --data out/data --seed 0 --no-generation --probe-data "${probe[@]}" \
    --json "out/eval_pooled_$RUN.json" > "out/eval_pooled_$RUN.md"
python leakage_pooled.py --workdir "$W" --datasets "${held[@]}" --json "out/leakage_pooled_$RUN.json" > "out/leakage_pooled_$RUN.md"
"${J[@]}" zeggs evaluate --workdir "$W" --data out/data --json "out/eval_$RUN.json" --seed 0 > "out/eval_$RUN.md"
"${J[@]}" zeggs evaluate --workdir "$W" --data out/data_heldout --json "out/eval_${RUN}_heldout.json" --seed 0 > "out/eval_${RUN}_heldout.md"
echo "eval_run $RUN: $(( $(date +%s) - t0 )) s"
