#!/usr/bin/env bash
# ZeroEGGS's claims on the generated motion (issue 37). Usage, from anywhere:
#   experiments/zeggs_claims/run.sh [RUN...]     # default: the 9 runs of runs.tsv that are not pilots
# Per run: trains out/RUN (resumes; skipped when done), then `jaxgest zeggs evaluate --claims` on the 8
# held-out script datasets and the real speech -> results/claims_RUN.json (stamped) and out/claims_RUN.md.
# Data (written once): out/data = jaxgest synth --seed 0 (training scripts), out/heldout/seedK, K = 1..8.
# Environment: PYTHON (default python), HELDOUT (default 8), SHARED (default: ../shared beside the repo),
# LEVER (default "small_s1 zs_tense_s0 zs_sad_s0"): runs also evaluated with --style-scale 2 (the lever);
# JOBS (default 1): with JOBS=N the runs are dealt round-robin to N queues, each pinned to one core (taskset) with
# XLA's intra-op threads at 1 -- more runs per hour than one run on all cores (docs/benchmarks.md).
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"; ROOT="$(cd "$HERE/../.." && pwd)"
PY="${PYTHON:-python}"; OUT="$HERE/out"; HELDOUT="${HELDOUT:-8}"
SHARED="${SHARED:-$ROOT/../shared}"; SPEECH_DIR="$SHARED/data/speech-gesture"
J=("$PY" -m jaxgest.cli)
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
mkdir -p "$OUT" "$HERE/results"
[ -f "$OUT/data/manifest.csv" ] || "${J[@]}" synth --out "$OUT/data" --seed 0 > /dev/null
held=()
for k in $(seq 1 "$HELDOUT"); do
  [ -f "$OUT/heldout/seed$k/manifest.csv" ] || "${J[@]}" synth --out "$OUT/heldout/seed$k" --seed "$k" > /dev/null
  held+=("$OUT/heldout/seed$k")
done
speech=(); for w in "$SPEECH_DIR"/zeggs/*.wav "$SPEECH_DIR"/beat2/*.wav; do [ -f "$w" ] && speech+=("$w"); done
runs=("$@"); [ ${#runs[@]} -gt 0 ] || mapfile -t runs < <(grep -v '^#' "$HERE/runs.tsv" | cut -f1 | grep -v '^pilot')
JOBS="${JOBS:-1}"; LEVER="${LEVER-small_s1 zs_tense_s0 zs_sad_s0}"
one_run() {
  local run="$1" line name preset steps seed exclude s t
  line=$(grep -P "^$run\t" "$HERE/runs.tsv") || { echo "run.sh: no run $run in runs.tsv" >&2; exit 2; }
  IFS=$'\t' read -r name preset steps seed exclude <<< "$line"
  ov=(); [ "$exclude" = "-" ] || ov=(--override "train.exclude_styles=$exclude")
  s=$(date +%s)
  "${J[@]}" zeggs train --data "$OUT/data" --workdir "$OUT/$name" --preset "$preset" --steps "$steps" \
      --seed "$seed" "${ov[@]}" > "$OUT/train_$name.log" 2>&1
  t=$(date +%s); echo "$name: trained in $(( t - s )) s ($steps steps)"
  sp=(); [ ${#speech[@]} -eq 0 ] || sp=(--speech "${speech[@]}")
  "${J[@]}" zeggs evaluate --workdir "$OUT/$name" --data "$OUT/data" --claims --heldout "${held[@]}" "${sp[@]}" \
      --json "$HERE/results/claims_$name.json" > "$OUT/claims_$name.md"
  echo "$name: evaluated in $(( $(date +%s) - t )) s"
  if [[ " $LEVER " == *" $name "* ]]; then  # the lever (README): the same model, style embeddings x 2
    "${J[@]}" zeggs evaluate --workdir "$OUT/$name" --data "$OUT/data" --claims --heldout "${held[@]}" \
        --style-scale 2 --json "$HERE/results/claims_${name}_scale2.json" > "$OUT/claims_${name}_scale2.md"
    echo "$name: lever (--style-scale 2) evaluated"
  fi
}
for run in "${runs[@]}"; do grep -qP "^$run\t" "$HERE/runs.tsv" || { echo "run.sh: no run $run in runs.tsv" >&2; exit 2; }; done
if [ "$JOBS" -le 1 ]; then
  for run in "${runs[@]}"; do one_run "$run"; done
else
  export XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1${XLA_FLAGS:+ $XLA_FLAGS}"
  pids=()
  for ((k = 0; k < JOBS; k++)); do
    ( taskset -cp "$(( k % $(nproc) ))" "$BASHPID" > /dev/null
      for ((i = k; i < ${#runs[@]}; i += JOBS)); do one_run "${runs[$i]}"; done ) &
    pids+=($!)
  done
  status=0; for p in "${pids[@]}"; do wait "$p" || status=1; done
  [ "$status" -eq 0 ] || { echo "run.sh: a run failed (see out/train_RUN.log)" >&2; exit 1; }
fi
"$PY" "$HERE/tables.py"
